"""The run's working resolution: the one asked for, made larger for a scene whose splats outnumber its pixels.

A capture of half a million splats seen at 256 px puts ~40 splats behind each pixel of the object; the run can
set their colours only in blends, and the face plate's lines and the texture's weave blur where the user looks
closer. :func:`working_resolution` makes the views' longest side large enough for at most
``SPLATS_PER_PIXEL`` splats per pixel of the object, never past ``dense_upscale`` times the resolution asked for;
a scene already that sparse (the donut, the fern) keeps the resolution asked for, and its run costs what it did.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch

from ..cameras.camera import Camera
from ..render import render
from ..scene.gaussians import GaussianScene
from .config import SPLATS_PER_PIXEL, TransferConfig
from .views import fit_cameras

PROBE_SIDE = 128
"""Longest side of the views the object's share of the frame is measured at (the share does not depend on it)."""
PROBE_VIEWS = 4
"""How many of the run's views, evenly spread, the share is measured over."""
OBJECT_ALPHA = 0.5
"""A pixel above this alpha shows the object."""
RESOLUTION_STEP = 16
"""A larger working resolution is a multiple of this: it and its half, the size the feature network sees at Feature
Scale 0.5, are whole 8 px rasterizer tiles."""


def working_resolution(
    scene: GaussianScene, views: Sequence[Camera] | int | None, config: TransferConfig, up: str
) -> int:
    """The longest side the run's views are rendered at: ``config.resolution``, or larger (at most
    ``config.dense_upscale`` times it) where ``scene``'s splats are denser than ``SPLATS_PER_PIXEL`` per pixel of the
    object in the views ``views`` and ``config`` make."""
    limit = int(config.resolution * config.dense_upscale)
    if limit <= config.resolution or len(scene) == 0:
        return config.resolution
    pixels = object_pixels(scene, views, config, up)
    if pixels <= 0.0:
        return config.resolution
    density = len(scene) / pixels
    if density <= SPLATS_PER_PIXEL:
        return config.resolution
    wanted = config.resolution * math.sqrt(density / SPLATS_PER_PIXEL)
    return min(limit, RESOLUTION_STEP * math.ceil(wanted / RESOLUTION_STEP))


@torch.no_grad()
def object_pixels(scene: GaussianScene, views: Sequence[Camera] | int | None, config: TransferConfig, up: str) -> float:
    """Mean count of the pixels that show ``scene`` in a view at ``config.resolution``: its pixels in a few small
    renders of the run's views, scaled by the square of the sides' ratio."""
    probes = fit_cameras(scene, views, PROBE_SIDE, config.n_views, up, kind=config.view_kind)
    spread = probes[:: max(1, len(probes) // PROBE_VIEWS)][:PROBE_VIEWS]
    covered = sum(float((_alpha(scene, cam, config.backend) > OBJECT_ALPHA).float().sum()) for cam in spread)
    return covered / len(spread) * (config.resolution / PROBE_SIDE) ** 2


def _alpha(scene: GaussianScene, camera: Camera, backend: str) -> torch.Tensor:
    """(H, W) coverage of ``scene`` from ``camera`` (colours at SH degree 0: only the coverage is read)."""
    return render(scene, [camera], backend=backend, render_depth=False, sh_degree=0).alphas[0]
