"""The run plan: everything a transfer decides before it optimises, decided once.

:func:`plan_run` makes it from the scene, the texture, the views, the settings and the region. The run
(``pipeline``), the orientation preview (CLI, API and Blender's worker) and the report read it, so
nothing is derived twice and no setting is replaced mid-run. ``asked`` is the config as given; ``config``
is the same with every automatic value resolved: the up axis of automatic views, the working resolution (larger
for a dense capture), the texture height
``texture_repeats`` implies, the layout's projection, whether the texture moves the splats, and the bank's depth
ratio.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import torch

from ..cameras.axes import axis_name
from ..cameras.camera import Camera
from ..cameras.generate import chosen_kind
from ..cameras.up import scene_up
from ..device import resolve_device
from ..errors import GT2GSError
from ..scene.gaussians import GaussianScene
from .bank import bank_depth_ratio
from .config import TransferConfig
from .content import content_and_hidden
from .grain import softened
from .gt2 import view_order
from .layout import LayoutFrame, layout_frame, projection, texture_height_for
from .region import region_mask, stylise_start, visible_rows
from .resolution import working_resolution
from .skips import redundant_views
from .stylise import moves_splats
from .texture import read_texture
from .views import ViewSet, fit_cameras

RESOLVED = ("up", "view_kind", "resolution", "texture_height", "layout_projection", "stylise_geometry", "depth_ratio")
"""The settings a plan resolves from the scene and its views (the report shows them beside what was asked)."""


@dataclass(frozen=True)
class RunPlan:
    """What a transfer of one scene, texture, views, settings and region will do, before it optimises."""

    asked: TransferConfig
    config: TransferConfig
    """``asked`` with its automatic values resolved (``RESOLVED``): what the run uses."""
    device: torch.device
    texture: np.ndarray
    """(H, W, 3) float32 in [0, 1]."""
    original: GaussianScene
    """The input scene, detached, on ``device``."""
    selected: torch.Tensor | None
    """The region as a mask over ``original`` (None: every splat)."""
    cameras: list[Camera]
    """The views at the run's resolution."""
    background: torch.Tensor
    content: ViewSet | None
    """The original's renders from ``cameras`` (None in a preview plan that lays nothing out)."""
    used: ViewSet | None
    """The views the optimisation uses: ``content`` less the ``dropped`` ones."""
    dropped: list[int]
    hidden: torch.Tensor | None
    """The rows of ``start`` no view sees, which the run leaves as they are (None: none skipped)."""
    region: torch.Tensor | None
    """The restyled rows among the splats the run optimises (None: all of them)."""
    start: GaussianScene
    """Every splat as the optimisation starts: at the result's SH degree, before colour transfer."""
    frame: LayoutFrame | None
    """The layout's frame (None: no layout and no texture size from repeats)."""

    @property
    def work(self) -> GaussianScene:
        """The splats the run optimises: ``start`` less the hidden rows."""
        return self.start if self.hidden is None else self.start.subset(~self.hidden)

    def resolved(self) -> dict[str, Any]:
        """The values the plan resolved, for the report."""
        return {name: getattr(self.config, name) for name in RESOLVED}


def plan_run(
    scene: GaussianScene,
    texture: np.ndarray | str | os.PathLike,
    views: Sequence[Camera] | int | None,
    config: TransferConfig,
    region: torch.Tensor | np.ndarray | None = None,
    *,
    preview: bool = False,
) -> RunPlan:
    """The plan of a transfer of ``scene`` with ``texture`` (a path or an (H, W, 3) array in [0, 1]) from
    ``views`` (cameras, a count of automatic views or None: the config's). A ``preview`` plan renders the
    views only when the layout or ``texture_repeats`` needs them (the sketch preview takes a fraction of a
    second), and leaves the depth ratio as asked then."""
    device = resolve_device(config.device)
    require_finite_scene(scene)
    image = run_texture(texture, config)
    original = scene.detach().to(device)
    selected = region_mask(region, len(original), device)
    framed = original if selected is None else original.subset(selected)
    up, kind = config.up, config.view_kind
    if views is None or isinstance(views, int):
        up = (axis_name(scene_up(framed)) or up) if up == "auto" else up
        kind = chosen_kind(framed, kind)
    resolution = working_resolution(framed, views, config, up)
    cameras = fit_cameras(framed, views, resolution, config.n_views, up, kind=kind, cut=config.cut_views)
    background = torch.tensor(config.background, dtype=original.dtype, device=device)
    start = stylise_start(original, selected, config.stylised_sh_degree)
    content = hidden = frame = None
    rows, dropped = selected, []
    if not preview or config.layout or config.texture_repeats > 0:
        content, hidden = content_and_hidden(original, cameras, background, config)
        hidden, rows = visible_rows(selected, hidden)
        dropped = _dropped_views(content, config)
        if config.layout or config.texture_repeats > 0:
            # sized on every selected splat, hidden ones too
            frame = layout_frame(framed, content, config)
    used = None if content is None else content.subset([v for v in range(len(cameras)) if v not in dropped])
    resolved = replace(_resolve(config, cameras, content, used, frame), up=up, view_kind=kind, resolution=resolution)
    return RunPlan(
        asked=config,
        config=resolved,
        device=device,
        texture=image,
        original=original,
        selected=selected,
        cameras=cameras,
        background=background,
        content=content,
        used=used,
        dropped=dropped,
        hidden=hidden,
        region=rows,
        start=start,
        frame=frame,
    )


def require_finite_scene(scene: GaussianScene) -> None:
    """Refuse a scene with NaN or Inf splats before any work (a reader refuses such a file unless asked to drop
    them; a scene built in Python can still hold them), saying how to leave them out."""
    bad = len(scene) - int(scene.finite_rows().sum())
    if bad:
        raise GT2GSError(
            f"the scene has {bad} of {len(scene)} Gaussians with NaN or Inf values; leave them out "
            "(scene.subset(scene.finite_rows()), or read the file with drop_invalid=True)"
        )


def run_texture(texture: np.ndarray | str | os.PathLike, config: TransferConfig) -> np.ndarray:
    """The texture as a run with ``config`` reads it (a path loaded, an array checked), softened by its
    ``texture_softness``: what the layout, the bank, the texture loss and the preview all see."""
    return softened(read_texture(texture), config.texture_softness)


def _dropped_views(content: ViewSet, config: TransferConfig) -> list[int]:
    """The views ``drop_views`` leaves out (they show almost nothing the others do not)."""
    cameras = content.cameras
    if not config.drop_views or len(cameras) <= 2:
        return []
    return redundant_views(cameras, content.depths, content.alphas, view_order(cameras), config.min_new_coverage)


def _resolve(
    config: TransferConfig,
    cameras: list[Camera],
    content: ViewSet | None,
    used: ViewSet | None,
    frame: LayoutFrame | None,
) -> TransferConfig:
    """``config`` with its automatic values taken from the views (``RESOLVED``)."""
    height = config.texture_height
    if frame is not None and config.texture_repeats > 0:
        height = texture_height_for(frame, content, config.n_scales)
    moves = moves_splats(cameras if used is None else used.cameras, config.stylise_geometry)
    return replace(
        config,
        texture_height=height,
        layout_projection=projection(cameras, config.layout_projection),
        stylise_geometry="on" if moves else "off",
        depth_ratio=config.depth_ratio if used is None else bank_depth_ratio(used, config),
    )
