"""The box layout turned about the up axis to the object's own faces (``box_fits_faces``).

The box projects the texture along three axes, each surface reading the plane its normal faces most (``layout``).
Taken from the first view alone, the axes met a boxy object at whatever angle that view stood: a face at 45° to
them blends two planes (the texture twice, out of step) and one at 30° shows it stretched by 1 / cos 30°. Turned
to the faces, each face lies on one plane, the texture undistorted; the same object turned in its file gets the
same layout. The faces' direction is the 4-fold mean of the visible surface's horizontal normal directions (a
face and its back, left and right side all count alike), over every view's pixels, each weighted by the surface
area it covers; where no direction stands out (a figure on flat ground, a drum) the axes stay as they were.
"""

from __future__ import annotations

import cmath
import math

import numpy as np
import torch

from ..cameras.warp import expected_depth
from .normals import SURFACE_ALPHA, normal_map
from .views import ViewSet

FACES_CONCENTRATION = 0.01
"""The 4-fold mean's length (0: directions all round, 1: every face on the box's axes) from which the box turns. The
guitar's flat body reads 0.49, a fitted toy box on its slab 0.02-0.045 and the donut 0.04, each mean's direction the
object's own (it follows a turn of the file); the robot on its ground reads 0.002, noise (docs/quality_log.md)."""


def faces_direction(views: ViewSet, axes: np.ndarray) -> tuple[float, float]:
    """(angle, concentration) of the visible surface's faces about ``axes[1]`` (up), from ``axes[0]`` (right) toward
    ``axes[2]`` (depth): the angle (radians, within +-45°) of the 4-fold mean of the horizontal normal directions
    and the mean's length (module notes). (0, 0) when no pixel shows a surface."""
    right, depth = (torch.from_numpy(np.asarray(axes[k], np.float64)) for k in (0, 2))
    moment, total = 0j, 0.0
    for camera, depth_map, alpha in zip(views.cameras, views.depths, views.alphas):
        normal, _, valid = normal_map(camera, depth_map.cpu(), alpha.cpu())
        z = expected_depth(depth_map.cpu(), alpha.cpu(), SURFACE_ALPHA).double()
        across, along = normal @ right, normal @ depth
        horizontal = across * across + along * along  # 1 on a wall, 0 on a floor
        weight = torch.where(valid, (z / camera.fy) ** 2 * horizontal, 0.0)
        turn = 4.0 * torch.atan2(along, across)
        moment += complex(float((weight * torch.cos(turn)).sum()), float((weight * torch.sin(turn)).sum()))
        total += float(weight.sum())
    if total <= 0.0:
        return 0.0, 0.0
    return cmath.phase(moment) / 4.0, abs(moment) / total


def turned_to_faces(axes: np.ndarray, views: ViewSet) -> np.ndarray:
    """``axes`` (rows: right, up, depth) turned about up onto the object's faces when they stand out
    (``FACES_CONCENTRATION``), else as they are."""
    angle, concentration = faces_direction(views, axes)
    if concentration < FACES_CONCENTRATION:
        return axes
    right, up, depth = axes
    cos, sin = math.cos(angle), math.sin(angle)
    return np.stack([cos * right + sin * depth, up, cos * depth - sin * right])
