"""Texture-transfer settings and the named presets (what the CLI's ``--preset`` and the UI offer)."""
from __future__ import annotations

from dataclasses import asdict, dataclass, fields, replace
from typing import Any


MAX_DEPTH_RATIO = 2.0
"""Largest measured depth ratio the bank follows: the authors' fixed one. A deeper scene keeps it, so
the farthest group's texture stays half the nearest's size (128 px at the default height), not a smudge."""


@dataclass(frozen=True)
class TransferConfig:
    """Every setting of a transfer run. Loss weights follow the paper's names (lambda_*)."""

    resolution: int = 256            # longest image side the views are rendered at
    n_views: int = 16                # automatic views when none are given
    stylise_steps: int = 200         # optimisation steps of the stylisation stage
    lr: float = 0.02                 # Adam learning rate on the DC colour coefficients
    stylised_sh_degree: int = 0      # SH degree of restyled colours: 0 = the same from every side (paper's code);
                                     # 1-3 train view-dependent bands too (lr/20), as NNFM baselines' fields do
    lambda_style: float = 1.0        # NNFM / texture loss weight
    lambda_content: float = 0.005    # content feature MSE (paper: 0.005 LLFF, 0.0005 360 scenes)
    lambda_tv: float = 0.02          # image total variation (paper 0.02)
    n_scales: int = 4                # texture scales = depth groups (paper K = 4)
    n_angles: int = 36               # rotations of the texture over 360 degrees (paper 360)
    texture_height: int = 256        # texture height at the nearest depth group (paper 256)
    cell_coverage: float = 0.5       # the texture loss counts feature cells covered beyond this fraction (1: wholly)
    object_backdrop: bool = False    # stylise renders show the object over its own mean colour, not the background:
                                     # no outline for the texture loss to trace (dark rims; halos of moved splats)
    depth_groups: bool = True        # match each feature cell only against its depth group's scale
    depth_ratio: float = 0.0         # farthest/nearest group depth the bank's scales follow: 0 = the views' own
                                     # (paper: Z_1/Z_k), at most MAX_DEPTH_RATIO; >= 1 fixed (authors' code: 2)
    color_transfer: bool = True      # ARF colour transfer before and after stylisation
    angle: float = 0.0               # orientation control: the texture's angle in the first view (degrees)
    gt2: bool = True                 # GT² loss: angles carried across views (False = NNFM on the texture as it lies)
    lambda_prior: float = 0.002      # prior angle cost per degree (authors' code: 100 = a hard constraint)
    afcm: bool = True                # Adaptive Fine-grained Control Module weights per feature cell
    lambda_depth: float = 0.8        # AFCM {lambda_d, lambda_f, lambda_phi} (paper 0.8, 0.8, 0.25)
    lambda_frequency: float = 0.8
    lambda_distortion: float = 0.25
    gpb: bool = True                 # Geometry Preservation Branch: correction phases between stylise phases
    stylise_geometry: bool = False   # the texture loss moves geometry too, as in the authors' code (bolder texture,
                                     # looser shape; the GPB pulls it back). Off: stylise phases train colours only
    rounds: int = 4                  # stylise/correct alternations (the steps are split evenly)
    correct_steps: int = 100         # GPB correction steps in all (geometry vs content images)
    lambda_scale: float = 0.1        # scale regulariser weight in the correction phases (paper 0.1)
    scale_ratio_limit: float = 10.0  # largest/second scale ratio tolerated before it is penalised (authors: 1)
    scale_ratio_from_start: bool = True  # ... or each Gaussian's own starting ratio if larger: the fit's needles
                                     # are geometry to preserve, only stylisation's new ones are penalised
    densify: bool = True             # clone/split by the DC-colour gradient in the first half of the rounds
    densify_every: int = 25          # stylise steps between densification events
    densify_grad_threshold: float = 2e-4  # mean |dL/d f_dc| that makes a Gaussian grow
    densify_max_growth: float = 1.5  # no densification once the scene has grown by this factor
    skip_hidden: bool = True         # freeze Gaussians no view sees (left out of rendering and optimisation)
    hidden_threshold: float = 0.1    # ... when their blending weight summed over all pixels of all views is below this
    skip_sh: bool = True             # render the original only up to the highest SH band with a non-zero coefficient
    adaptive_angles: bool = False    # fewer bank angles for a texture with no strong local orientation (n_angles = most)
    dedup_threshold: float = 0.0     # drop bank rows with a twin above this cosine in their depth group (0 = off)
    match_channels: int = 64         # match on this many PCA channels of the bank (0 = all; targets stay full)
    drop_views: bool = False         # drop views that add less than min_new_coverage of unseen covered pixels
    min_new_coverage: float = 0.02
    plateau_window: int = 16         # stop a phase when the mean loss of this many steps stops falling (0 = off)
    plateau_tol: float = 0.01        # ... by less than this fraction of the window before
    feature_scale: float = 0.5       # renders are resized by this before VGG (paper 0.5)
    mixed_precision: bool = True     # VGG convolutions in float16 on a CUDA GPU (float32 on the CPU)
    bank_cache: bool = True          # keep texture banks on disk across runs (cache_dir or $GT2GS_CACHE_DIR)
    reuse_content: bool = True       # reuse the last run's content renders and hidden set (same scene + views)
    background: tuple[float, float, float] = (1.0, 1.0, 1.0)
    features: str = "auto"           # feature network preference (see features.load_feature_extractor)
    weights_path: str | None = None  # explicit weights file or folder
    device: str = "auto"             # auto | cpu | cuda
    threads: int = 0                 # CPU threads for torch and the C++ rasterizer (0 = one per physical core)
    backend: str = "auto"            # rasterizer backend
    seed: int = 0
    preview_every: int = 10          # steps between preview frames sent to the progress callback
    evaluate: bool = True            # measure the paper's metrics at the end (report["metrics"])
    cache_dir: str | None = None     # texture-bank cache (default: $GT2GS_CACHE_DIR, else ~/.cache/gt2gs_blender/banks)

    def __post_init__(self) -> None:
        positive = ("resolution", "n_views", "n_scales", "n_angles", "texture_height", "preview_every", "rounds",
                    "densify_every")
        for name in positive:
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be at least 1, got {getattr(self, name)}")
        if self.stylise_steps < 0 or self.correct_steps < 0 or self.lr <= 0:
            raise ValueError(f"need stylise_steps >= 0, correct_steps >= 0 and lr > 0, got {self.stylise_steps}, "
                             f"{self.correct_steps}, {self.lr}")
        if not 0.0 <= self.dedup_threshold <= 1.0 or self.match_channels < 0 or self.plateau_window < 0:
            raise ValueError(f"need 0 <= dedup_threshold <= 1, match_channels >= 0 and plateau_window >= 0, got "
                             f"{self.dedup_threshold}, {self.match_channels}, {self.plateau_window}")
        if not 0.0 < self.feature_scale <= 4.0 or not 0.0 <= self.min_new_coverage <= 1.0:
            raise ValueError(f"need 0 < feature_scale <= 4 and 0 <= min_new_coverage <= 1, got {self.feature_scale}, "
                             f"{self.min_new_coverage}")
        if not 0 <= self.stylised_sh_degree <= 3:
            raise ValueError(f"stylised_sh_degree must be 0..3, got {self.stylised_sh_degree}")
        if not 0.0 <= self.cell_coverage <= 1.0:
            raise ValueError(f"cell_coverage must be in 0..1, got {self.cell_coverage}")
        if self.depth_ratio != 0.0 and not 1.0 <= self.depth_ratio <= 16.0:
            raise ValueError(f"depth_ratio must be 0 (measured) or 1..16, got {self.depth_ratio}")
        if self.threads < 0:
            raise ValueError(f"threads must be >= 0 (0 = one per physical core), got {self.threads}")
        if self.hidden_threshold < 0:
            raise ValueError(f"hidden_threshold must be >= 0, got {self.hidden_threshold}")
        if self.device not in ("auto", "cpu", "cuda"):
            raise ValueError(f"device must be auto, cpu or cuda, got {self.device!r}")

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    def with_overrides(self, **overrides: Any) -> "TransferConfig":
        """A copy with the given fields changed (None values are ignored: 'not given')."""
        known = {f.name for f in fields(self)}
        unknown = set(overrides) - known
        if unknown:
            raise ValueError(f"unknown transfer settings: {', '.join(sorted(unknown))}")
        return replace(self, **{k: v for k, v in overrides.items() if v is not None})


PAPER_SCHEDULE: dict[str, Any] = dict(
    resolution=1008,         # LLFF at 1/4 of 4032 px, as the paper trains
    stylise_steps=20 * 80,   # 10 rounds x (80 stylise + 200 correct + 80 stylise + 200 correct)
    correct_steps=20 * 200,
    rounds=20,
    n_scales=4, n_angles=360, texture_height=256,
    lambda_style=2.0, lambda_tv=0.02, lambda_prior=100.0,
    lambda_depth=0.8, lambda_frequency=0.8, lambda_distortion=0.25,
    lambda_scale=0.1, scale_ratio_limit=1.0, scale_ratio_from_start=False,
    stylise_geometry=True,   # the authors' stylise phases step every parameter, geometry included
    plateau_window=0,        # the paper's step counts, run in full
    match_channels=0,        # and its matching on every channel
)
"""The paper's schedule and weights (paper §4 and appendix, the authors' code for lambda_p and the
scale regulariser); its 400 + 400 colour-transfer fitting steps are exact SH transforms here."""

PRESETS: dict[str, TransferConfig] = {
    "preview": TransferConfig(resolution=128, n_views=8, stylise_steps=40, correct_steps=20, rounds=2, n_scales=2,
                              n_angles=8, texture_height=128, evaluate=False, preview_every=5),
    "fast": TransferConfig(stylise_steps=300, correct_steps=150, n_angles=72),
    "balanced": TransferConfig(resolution=384, n_views=24, stylise_steps=600, correct_steps=300, rounds=6,
                               n_angles=72),
    "paper-llff": TransferConfig(**PAPER_SCHEDULE, lambda_content=0.005),
    "paper-360": TransferConfig(**PAPER_SCHEDULE, lambda_content=0.0005),
}
"""``preview`` gives a first look in seconds, ``fast`` a usable result in minutes on a CPU (on the
donut, 16 views at 256 px: 300 + 150 steps and 72 angles bring texture match within 5 % of
``balanced`` where the defaults' 200 + 100 steps and 36 angles stayed 10 % off, bench/tradeoff.py),
``balanced`` more views, resolution and texture orientations; ``paper-llff`` and ``paper-360`` are
the paper's settings exactly (hours on a CPU: meant for a GPU)."""


def preset(name: str, **overrides: Any) -> "TransferConfig":
    """The named preset with optional overrides."""
    if name not in PRESETS:
        raise ValueError(f"unknown preset {name!r}; choose one of {', '.join(PRESETS)}")
    return PRESETS[name].with_overrides(**overrides)
