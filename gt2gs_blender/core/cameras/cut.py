"""Views cut to the part of their images their object fills: no empty bands beside a tall guitar."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ..scene.gaussians import GaussianScene
from .camera import Camera

CUT_SHARE = 0.999
"""A view cut to its object keeps this share of the splat centres in front of it inside, along each axis: a few
floaters do not decide its size."""
CUT_SAMPLE = 65536
"""The cut reads at most this many of the centres, evenly strided: the share needs no more (a 500,000-splat capture
took 0.5 s to project whole for 16 views)."""
CUT_MARGIN = 1.1
CUT_PAD = 8
"""It keeps their extent times this margin and this many pixels a side more: the outermost splats' own footprints."""
CUT_STEP = 8
"""Views are cut by this many pixels a side at a time: a size of whole 8 px rasterizer tiles, and of whole tiles at
half size (Feature Scale 0.5), stays so, and the pixel grid stays where it was."""


def cut_to_points(
    cameras: Sequence[Camera], points: np.ndarray, margin: float = CUT_MARGIN, pad: int = CUT_PAD
) -> list[Camera]:
    """Views of one size cut about their centres to the part of their images that ``points`` (world, (N, 3)) fill
    in any of them (``CUT_SHARE`` of the points in front along each axis), with ``margin`` and ``pad``, never grown
    and cut by ``CUT_STEP`` a side: a tall guitar framed in square views leaves half of each empty."""
    if not cameras or len(points) == 0:
        return list(cameras)
    points = points[:: math.ceil(len(points) / CUT_SAMPLE)]
    size = np.array([cameras[0].width, cameras[0].height])
    if any((cam.width, cam.height) != tuple(size) for cam in cameras):
        raise ValueError("cut_to_points needs views of one size")
    reach = np.zeros(2)
    for cam in cameras:
        uv, depth = cam.project(points)
        if not np.any(depth > 0):
            return list(cameras)
        reach = np.maximum(reach, np.quantile(np.abs(uv[depth > 0] - [cam.cx, cam.cy]), CUT_SHARE, axis=0))
    wanted = 2.0 * (reach * margin + pad)
    width, height = (size - 2 * CUT_STEP * np.floor(np.maximum(size - wanted, 0.0) / (2 * CUT_STEP))).astype(int)
    return [cam.cropped(int(width), int(height)) for cam in cameras]


def cut_to_scene(cameras: Sequence[Camera], scene: GaussianScene) -> list[Camera]:
    """:func:`cut_to_points` of the scene's splat centres."""
    return cut_to_points(cameras, scene.means.detach().double().cpu().numpy())
