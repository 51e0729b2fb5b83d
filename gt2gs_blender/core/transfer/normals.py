"""The surface normal under each splat, for the box layout's blend of its three planes.

Normals come from the views' rendered depth (blurred, so sprinkles and specks do not flip the
plane a splat samples), each splat taking the normal of the pixel it projects to in the view that
sees it most frontally; splats no view sees take their nearest seen neighbour's. The smallest
scale axis of a 3DGS splat is a poor normal (a third within 25° of the surface's on the donut).
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np
import torch
import torch.nn.functional as F

from ..cameras.camera import Camera
from ..cameras.warp import backproject, expected_depth, reproject
from ..scene.gaussians import GaussianScene

SURFACE_ALPHA = 0.9
"""Pixels at least this opaque carry a surface normal."""
NORMAL_BLUR_PX = 3.0
"""Gaussian blur (pixels) of the depth before differencing: normals of the surface, not of its specks."""
DEPTH_TOLERANCE = 0.03
"""A splat is on the surface a pixel shows when its depth is within this fraction of the pixel's."""


@torch.no_grad()
def surface_normals(
    scene: GaussianScene, cameras: Sequence[Camera], depths: Sequence[torch.Tensor], alphas: Sequence[torch.Tensor]
) -> torch.Tensor:
    """(N, 3) unit normal per splat from the views' rendered depth (module notes)."""
    n = len(scene)
    best = torch.full((n,), -1.0, dtype=torch.float64)
    normals = torch.zeros(n, 3, dtype=torch.float64)
    means = scene.means.detach().cpu()
    for camera, depth, alpha in zip(cameras, depths, alphas):
        pixel_normals, pixel_facing, valid = normal_map(camera, depth.cpu(), alpha.cpu())
        uv, z = reproject(means, camera)
        col, row = uv[:, 0].floor().long(), uv[:, 1].floor().long()
        inside = (z > 0) & (col >= 0) & (col < camera.width) & (row >= 0) & (row < camera.height)
        col, row = col.clamp(0, camera.width - 1), row.clamp(0, camera.height - 1)
        surface = expected_depth(depth.cpu(), alpha.cpu(), SURFACE_ALPHA).double()[row, col]
        seen = inside & valid[row, col] & ((z - surface).abs() <= DEPTH_TOLERANCE * surface)
        facing = torch.where(seen, pixel_facing[row, col], torch.full_like(z, -1.0))
        better = facing > best
        best = torch.where(better, facing, best)
        normals[better] = pixel_normals[row[better], col[better]]
    return _fill_unseen(means, normals, best >= 0).float().to(scene.device)


def normal_map(camera: Camera, depth: torch.Tensor, alpha: torch.Tensor) -> tuple[torch.Tensor, ...]:
    """Per pixel: the unit normal facing the camera (H,W,3), its cosine to the ray (H,W) and
    whether the pixel and its blurred neighbourhood are opaque surface (H,W)."""
    covered = (alpha >= SURFACE_ALPHA).double().numpy()
    z = expected_depth(depth, alpha, SURFACE_ALPHA).double().numpy()
    weight = cv2.GaussianBlur(covered, (0, 0), NORMAL_BLUR_PX)
    smooth = cv2.GaussianBlur(z, (0, 0), NORMAL_BLUR_PX) / np.maximum(weight, 1e-6)
    points = backproject(torch.from_numpy(smooth), camera)
    dx, dy = torch.zeros_like(points), torch.zeros_like(points)
    dx[:, 1:-1] = points[:, 2:] - points[:, :-2]
    dy[1:-1] = points[2:] - points[:-2]
    normal = F.normalize(torch.cross(dx, dy, dim=-1), dim=-1)
    to_camera = F.normalize(torch.from_numpy(camera.center) - points, dim=-1)
    facing = (normal * to_camera).sum(-1)
    normal = torch.where(facing[..., None] < 0, -normal, normal)
    valid = torch.from_numpy((covered > 0) & (weight > 0.99)) & (normal.norm(dim=-1) > 0.5)
    return normal, facing.abs(), valid


EXACT_NEAREST = dict(algorithm=4, leaf_max_size=10)
"""FLANN's single k-d tree: exact and deterministic nearest neighbours (the randomised forest gave a
run-to-run different neighbour for ~10 % of queries, so the same scene laid out differently), and faster
(0.2 s against 2.5 s for 100k queries in 400k points, 2 cores)."""


def _fill_unseen(means: torch.Tensor, normals: torch.Tensor, seen: torch.Tensor) -> torch.Tensor:
    """Normals of splats no view sees, from their nearest seen splat (the view's up when none is seen)."""
    if bool(seen.all()):
        return normals
    if not bool(seen.any()):
        return torch.tensor([0.0, 0.0, 1.0], dtype=normals.dtype).expand_as(normals).clone()
    points = means.float().numpy()
    index = cv2.flann_Index(np.ascontiguousarray(points[seen.numpy()]), EXACT_NEAREST)
    nearest, _ = index.knnSearch(np.ascontiguousarray(points[~seen.numpy()]), 1)
    filled = normals.clone()
    filled[~seen] = normals[seen][torch.from_numpy(nearest[:, 0].astype(np.int64))]
    return filled
