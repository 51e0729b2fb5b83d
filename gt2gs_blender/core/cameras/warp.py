"""Reprojection between posed views through rendered depth: exact for a rendered scene, so the
consistency metrics need no optical flow, and the GT^2 loss can carry matches from view to view.

Conventions (docs/architecture.md, "Conventions"): OpenCV camera frame, pixel centres at +0.5 (pixel (row i, col j) is
at u = j + 0.5, v = i + 0.5 and u = fx*x/z + cx). Depths here are *expected* depths (the
rasterizer's sum T*alpha*z divided by alpha, see :func:`expected_depth`); 0 marks "no surface".
Geometry is computed in float64.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F

from .camera import Camera

MIN_ALPHA = 0.5
"""Coverage below which a pixel has no reliable surface (its depth mixes background)."""
REL_TOL = 0.02
"""Relative depth tolerance of the occlusion test."""
_MIN_Z = 1e-6


@dataclass
class Warp:
    """A source image resampled into the destination view.

    ``image`` (H,W,C) is zero where ``valid`` (H,W) is False; ``src_uv`` (H,W,2) float64 is the flow as a
    mapping: for every destination pixel, the continuous source pixel coordinates (u, v) it comes from.
    """

    image: torch.Tensor
    valid: torch.Tensor
    src_uv: torch.Tensor


def expected_depth(depth: torch.Tensor, alpha: torch.Tensor, min_alpha: float = MIN_ALPHA) -> torch.Tensor:
    """Rendered depth sum T*alpha*z divided by alpha where alpha >= ``min_alpha``, else 0."""
    covered = alpha >= min_alpha
    return torch.where(covered, depth / alpha.clamp_min(min_alpha), torch.zeros_like(depth))


def pixel_centres(camera: Camera, device: torch.device | str | None = None) -> torch.Tensor:
    """(H,W,2) float64 pixel-centre coordinates (u, v) = (j + 0.5, i + 0.5)."""
    v, u = torch.meshgrid(
        torch.arange(camera.height, dtype=torch.float64, device=device) + 0.5,
        torch.arange(camera.width, dtype=torch.float64, device=device) + 0.5,
        indexing="ij",
    )
    return torch.stack([u, v], dim=-1)


def backproject(depth: torch.Tensor, camera: Camera) -> torch.Tensor:
    """World points (H,W,3) float64 of every pixel centre at its expected ``depth`` (H,W)."""
    _check_size(depth, camera, "depth")
    z = depth.to(torch.float64)
    uv = pixel_centres(camera, depth.device)
    cam = torch.stack([(uv[..., 0] - camera.cx) / camera.fx * z, (uv[..., 1] - camera.cy) / camera.fy * z, z], -1)
    viewmat = _viewmat(camera, depth.device)
    return (cam - viewmat[:3, 3]) @ viewmat[:3, :3]  # R^T (p - t), rows as vectors


def reproject(points: torch.Tensor, camera: Camera) -> tuple[torch.Tensor, torch.Tensor]:
    """Pixel coordinates (...,2) and camera depths (...) of world points (...,3), float64.

    ``uv`` is meaningful only where the depth is positive.
    """
    viewmat = _viewmat(camera, points.device)
    cam = points.to(torch.float64) @ viewmat[:3, :3].T + viewmat[:3, 3]
    z = cam[..., 2]
    safe = torch.where(z.abs() < _MIN_Z, torch.full_like(z, _MIN_Z), z)
    uv = torch.stack([camera.fx * cam[..., 0] / safe + camera.cx, camera.fy * cam[..., 1] / safe + camera.cy], -1)
    return uv, z


def sample(image: torch.Tensor, uv: torch.Tensor, mode: str = "bilinear") -> torch.Tensor:
    """Values of ``image`` (H,W,C) at continuous pixel coordinates ``uv`` (...,2); edges clamp."""
    height, width = image.shape[:2]
    size = torch.tensor([width, height], dtype=torch.float64, device=uv.device)
    grid = (2.0 * uv / size - 1.0).to(image.dtype).reshape(1, -1, 1, 2)
    out = F.grid_sample(image.permute(2, 0, 1)[None], grid, mode=mode, padding_mode="border", align_corners=False)
    return out[0, :, :, 0].T.reshape(*uv.shape[:-1], image.shape[2])


def warp_image(
    src_image: torch.Tensor,
    src_depth: torch.Tensor,
    src_cam: Camera,
    dst_cam: Camera,
    dst_depth: torch.Tensor,
    *,
    src_alpha: torch.Tensor | None = None,
    dst_alpha: torch.Tensor | None = None,
    min_alpha: float = MIN_ALPHA,
    rel_tol: float = REL_TOL,
    mode: str = "bilinear",
) -> Warp:
    """Resample ``src_image`` (H,W,C) into the destination view using the *destination* depth.

    Each destination pixel centre is lifted to 3D with ``dst_depth``, projected into the source
    and sampled there (``mode`` ``bilinear``, or ``nearest`` for labels). It is valid when its
    depth is positive, it lands inside the source image, the source depth there agrees within
    ``rel_tol`` (occlusion test: a nearer surface, or none, in the source fails), and, where alpha
    maps are given, both pixels are covered (alpha >= ``min_alpha``).
    """
    _check_size(src_image, src_cam, "source image")
    _check_size(src_depth, src_cam, "source depth")
    uv, z = reproject(backproject(dst_depth, dst_cam), src_cam)
    inside = (uv[..., 0] >= 0) & (uv[..., 0] <= src_cam.width) & (uv[..., 1] >= 0) & (uv[..., 1] <= src_cam.height)
    valid = (dst_depth > 0) & (z > _MIN_Z) & inside
    planes = [src_image, src_depth[..., None]] + ([] if src_alpha is None else [src_alpha[..., None]])
    sampled = sample(torch.cat([p.to(src_image.dtype) for p in planes], dim=-1), uv, mode)
    channels = src_image.shape[-1]
    valid &= (sampled[..., channels].to(torch.float64) - z).abs() <= rel_tol * z
    if src_alpha is not None:
        valid &= sampled[..., channels + 1] >= min_alpha
    if dst_alpha is not None:
        valid &= dst_alpha >= min_alpha
    image = torch.where(valid[..., None], sampled[..., :channels], torch.zeros_like(sampled[..., :channels]))
    return Warp(image=image, valid=valid, src_uv=uv)


def _viewmat(camera: Camera, device: torch.device) -> torch.Tensor:
    """The camera's world->camera 4x4 as a float64 tensor (a copy: the array is read-only)."""
    return torch.tensor(camera.world_to_cam, dtype=torch.float64, device=device)


def _check_size(array: torch.Tensor, camera: Camera, what: str) -> None:
    """ValueError unless ``array`` is (H,W[,C]) of the camera's image size."""
    if tuple(array.shape[:2]) != (camera.height, camera.width):
        size = f"{camera.height}x{camera.width}"
        raise ValueError(f"{what} is {tuple(array.shape[:2])}, camera {camera.name!r} is {size}")
