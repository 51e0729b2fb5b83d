"""Whether a scene shows at all in the views a transfer would use, checked before any work starts.

Cameras from another scene (or looking away), or a file of fully transparent Gaussians, leave every
view empty; the transfer would then fail deep inside (the colour transfer has no pixel to fit) or
"succeed" without changing anything. :func:`require_visible` turns that into one error naming the
PLY, saying why nothing is seen and what to check.
"""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np
import torch

from ..cameras.camera import Camera
from ..device import resolve_device
from ..errors import InputFileError
from ..raster_rules import ALPHA_MIN
from ..render import render
from ..scene.gaussians import GaussianScene
from .config import TransferConfig
from .region import region_mask
from .views import fit_cameras


@torch.no_grad()
def visible_in_any(scene: GaussianScene, cameras: Sequence[Camera], backend: str = "auto") -> bool:
    """Whether some pixel of some camera gets a positive alpha; renders one camera at a time and
    stops at the first that shows anything, so a visible scene costs one alpha-only render."""
    probe = torch.zeros(len(scene), 1, dtype=scene.dtype, device=scene.device)
    for cam in cameras:
        if bool((render(scene, [cam], colors=probe, render_depth=False, backend=backend).alphas > 0).any()):
            return True
    return False


def require_visible(
    scene: GaussianScene,
    views: Sequence[Camera] | int | None,
    config: TransferConfig,
    ply_path: str | os.PathLike,
    views_source: str | None,
    region: torch.Tensor | np.ndarray | None = None,
) -> None:
    """Raise InputFileError naming ``ply_path`` when the transfer's views (the cameras ``transfer`` makes
    from ``views``, ``config`` and ``region``) would show none of ``scene``; ``views_source`` names the
    cameras file the views came from (None: automatic views)."""
    n = len(scene)
    if n == 0:
        raise InputFileError(ply_path, "the file holds no Gaussians: there is nothing to re-texture")
    device = resolve_device(config.device)
    scene = scene.detach().to(device)
    selected = region_mask(region, n, device)
    framed = scene if selected is None else scene.subset(selected)
    cameras = fit_cameras(
        framed, views, config.resolution, config.n_views, config.up, kind=config.view_kind, cut=config.cut_views
    )
    if visible_in_any(scene, cameras, config.backend):
        return
    where = f"the {len(cameras)} views of {views_source}" if views_source else f"the {len(cameras)} automatic views"
    if not bool((scene.opacities >= ALPHA_MIN).any()):  # fainter splats never add to a pixel
        why = f"all {n:,} Gaussians are fully transparent (opacity below 1/255); check the file's opacity values"
    else:
        why = f"all {n:,} Gaussians are behind the cameras or outside their images" + (
            "; check that the cameras belong to this scene (same coordinate frame and scale)" if views_source else ""
        )
    raise InputFileError(ply_path, f"no Gaussian is visible in any of {where}: {why}")
