"""The settings that trade time for nothing a user sees (skips, caches, early stops, the closing measures): the part
of ``config.TransferConfig`` the Speed settings group holds, its own dataclass as the machine's is (``machine.py``)."""

from __future__ import annotations

from dataclasses import dataclass

from .machine import MachineSettings
from .setting import setting


@dataclass(frozen=True)
class SpeedSettings(MachineSettings):
    """The speed part of a transfer's settings (``TransferConfig`` derives from it)."""

    drop_views: bool = setting(
        False, "Drop Redundant Views", "Leave out views that show almost nothing the others do not", "speed"
    )
    min_new_coverage: float = setting(
        0.02,
        "New Coverage",
        "A view is redundant when it adds less than this share of unseen pixels",
        "speed",
        min=0.0,
        max=1.0,
    )
    adaptive_angles: bool = setting(
        False, "Adaptive Rotations", "Fewer rotations for a texture with no strong direction", "speed"
    )
    dedup_threshold: float = setting(
        0.0,
        "Deduplicate Bank",
        "Drop near-identical bank entries above this similarity (0 = keep all)",
        "speed",
        min=0.0,
        max=1.0,
    )
    match_channels: int = setting(
        64,
        "Matching Channels",
        "Compare the texture's features on this many of their strongest directions, which is faster and barely "
        "changes the match (0: all channels, slower)",
        "speed",
        min=0,
        soft_max=256,
        switch=("--full-matching", 0, "match on all channels, not 64 principal components"),
    )
    bank_cache: bool = setting(True, "Cache Texture Banks", "Keep texture banks on disk for the next run", "speed")
    skip_hidden: bool = setting(
        True, "Skip Hidden Splats", "Leave splats no view sees out of the optimisation (same result, faster)", "speed"
    )
    hidden_threshold: float = setting(
        0.1,
        "Hidden Below",
        "A splat is hidden when all views together show less than this many pixels of it",
        "speed",
        unit="px",
        min=0.0,
        soft_max=10.0,
    )
    skip_sh: bool = setting(
        True,
        "Skip Unused SH Bands",
        "Render the original only up to its highest spherical-harmonic band in use",
        "speed",
    )
    reuse_weights: bool = setting(
        True,
        "Reuse Still Renders",
        "While the splats hold still, redraw each view from its compositing weights kept in memory "
        "(same result, faster)",
        "speed",
    )
    feature_window: bool = setting(
        True,
        "Features Near Splats",
        "Run the feature network only on the part of each view near the splats and reuse the empty backdrop's "
        "features elsewhere (same result, faster on an object that leaves much of the view empty)",
        "speed",
    )
    cut_views: bool = setting(
        True,
        "Views Fit Object",
        "Leave out the empty bands beside the object in the automatic views (the same pixels of the object, faster "
        "on a tall or wide one)",
        "speed",
    )
    plateau_window: int = setting(
        16,
        "Plateau Window",
        "Stop a phase when the mean loss of this many steps stops falling (0 = run all)",
        "speed",
        unit="steps",
        min=0,
        soft_max=100,
        switch=("--no-plateau-stop", 0, "run every step of every phase"),
    )
    plateau_tol: float = setting(
        0.01,
        "Plateau Tolerance",
        "A phase has stopped falling when its loss drops by less than this fraction",
        "speed",
        min=0.0,
        max=1.0,
    )
    reuse_content: bool = setting(
        True, "Reuse Content Renders", "Reuse the last run's renders of the original (same scene and views)", "speed"
    )
    evaluate: bool = setting(
        True, "Measure Result", "Measure consistency, content and texture match at the end", "speed"
    )
