"""Projection of 3D Gaussians into a batch of pinhole cameras (EWA splatting), in torch autograd.

Produces one *entry* per visible (camera, Gaussian) pair: 2D mean, conic, depth, opacity, colour
and the inclusive range of 8x8 tiles whose pixel centres can see alpha >= 1/255 from it. Every
backend composites these same entries, so they share culling and footprint rules exactly.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from ..raster_rules import ALPHA_MIN, EPS2D, FOV_CLAMP, TILE
from ..scene.gaussians import quats_to_rotmats
from .sh import eval_sh, sh0_to_rgb

NEAR_PLANE = 0.01
FAR_PLANE = 1e10
"""Default clipping depths of a render (camera-space z)."""


@dataclass
class Footprints:
    """Where each visible (camera, Gaussian) entry lands on screen: what density control reads.

    Every backend gives these, so densification works the same whichever one renders."""

    cam_ids: torch.Tensor  # (M,) int64
    gauss_ids: torch.Tensor  # (M,) int64
    means2d: torch.Tensor  # (M, 2) pixels, differentiable (retain_grad() before backward for its gradient)
    radii: torch.Tensor  # (M, 2) half-extents in pixels of the footprint


@dataclass
class Projection:
    """Visible entries of all cameras; tensors are (M, ...) and differentiable where float."""

    cam_ids: torch.Tensor  # (M,) int64, camera of each entry
    gauss_ids: torch.Tensor  # (M,) int64, Gaussian of each entry
    means2d: torch.Tensor  # (M, 2) pixels, pixel centres at +0.5
    conics: torch.Tensor  # (M, 3) inverse 2D covariance (a, b, c)
    depths: torch.Tensor  # (M,) camera-space z
    opacities: torch.Tensor  # (M,)
    colors: torch.Tensor  # (M, D)
    tile_bbox: torch.Tensor  # (M, 4) int32 inclusive tile rectangle x0, y0, x1, y1
    radii: torch.Tensor  # (M, 2) half-extents in pixels of the alpha >= 1/255 footprint

    def footprints(self) -> Footprints:
        """The entries' screen positions and extents (the same tensors, so gradients reach them)."""
        return Footprints(self.cam_ids, self.gauss_ids, self.means2d, self.radii)


def tile_grid(width: int, height: int) -> tuple[int, int]:
    """Number of 8x8 tiles across and down an image."""
    return (width + TILE - 1) // TILE, (height + TILE - 1) // TILE


def _covariances_3d(quats: torch.Tensor, scales: torch.Tensor) -> torch.Tensor:
    """World-space covariances R S S^T R^T, (N, 3, 3)."""
    m = quats_to_rotmats(quats) * scales[:, None, :]
    return m @ m.transpose(1, 2)


def _visible_pairs(
    p_cam: torch.Tensor,
    ks: torch.Tensor,
    gaussians_ok: torch.Tensor,
    near: float,
    far: float,
) -> torch.Tensor:
    """(camera, Gaussian) index pairs in front of the near plane with a chance of alpha >= 1/255.

    Pairs whose 2D mean is not a finite float (a mean far off to the side: fx * x / z overflows) are
    dropped here, before the differentiable chain: culled later, their 0 gradient would meet the
    Inf and become NaN. ``gaussians_ok`` (N,) marks Gaussians with usable opacity, scale and rotation.
    """
    z = p_cam[..., 2]
    ok = (z > near) & (z < far) & gaussians_ok[None, :] & torch.isfinite(p_cam).all(-1)
    with torch.no_grad():
        uv = p_cam[..., :2] * ks[:, None, [0, 1], [0, 1]] / z[..., None] + ks[:, None, [0, 1], [2, 2]]
    return (ok & torch.isfinite(uv).all(-1)).nonzero()


def _jacobians(p: torch.Tensor, k: torch.Tensor, width: int, height: int) -> torch.Tensor:
    """Perspective Jacobians d(u,v)/d(x,y,z), (M, 2, 3), with 3DGS's frustum clamp."""
    fx, fy, cx, cy = k[:, 0, 0], k[:, 1, 1], k[:, 0, 2], k[:, 1, 2]
    x, y, z = p.unbind(-1)
    lim_x_pos = (width - cx) / fx + (FOV_CLAMP - 1.0) * 0.5 * width / fx
    lim_x_neg = cx / fx + (FOV_CLAMP - 1.0) * 0.5 * width / fx
    lim_y_pos = (height - cy) / fy + (FOV_CLAMP - 1.0) * 0.5 * height / fy
    lim_y_neg = cy / fy + (FOV_CLAMP - 1.0) * 0.5 * height / fy
    tx = z * torch.minimum(torch.maximum(x / z, -lim_x_neg), lim_x_pos)
    ty = z * torch.minimum(torch.maximum(y / z, -lim_y_neg), lim_y_pos)
    zero = torch.zeros_like(z)
    rz = 1.0 / z
    return torch.stack([fx * rz, zero, -fx * tx * rz * rz, zero, fy * rz, -fy * ty * rz * rz], dim=-1).reshape(-1, 2, 3)


def _tile_rects(means2d: torch.Tensor, radii: torch.Tensor, width: int, height: int) -> torch.Tensor:
    """Inclusive tile rectangles covering every pixel centre inside the footprint boxes (M, 4) int32."""
    tiles_x, tiles_y = tile_grid(width, height)
    with torch.no_grad():
        lo = torch.ceil(means2d - radii - 0.5)
        hi = torch.floor(means2d + radii - 0.5)
        size = torch.tensor([width - 1, height - 1], dtype=lo.dtype, device=lo.device)
        lo = lo.clamp(min=0.0)
        hi = torch.minimum(hi, size)
        tmax = torch.tensor([tiles_x - 1, tiles_y - 1], dtype=lo.dtype, device=lo.device)
        t0 = torch.div(lo, TILE, rounding_mode="floor").clamp(max=tmax)
        t1 = torch.div(hi, TILE, rounding_mode="floor").clamp(min=-1.0)
        return torch.cat([t0, t1], dim=-1).to(torch.int32)


def project(
    means: torch.Tensor,
    quats: torch.Tensor,
    scales: torch.Tensor,
    opacities: torch.Tensor,
    colors: torch.Tensor,
    viewmats: torch.Tensor,
    ks: torch.Tensor,
    width: int,
    height: int,
    *,
    sh_degree: int | None,
    near_plane: float,
    far_plane: float,
    with_depth: bool,
) -> Projection:
    """Cull, project and colour every (camera, Gaussian) pair; see the module docstring."""
    rot, trans = viewmats[:, :3, :3], viewmats[:, :3, 3]
    p_cam_all = torch.einsum("bij,nj->bni", rot, means) + trans[:, None, :]
    with torch.no_grad():
        gaussians_ok = (opacities >= ALPHA_MIN) & torch.isfinite(scales).all(-1) & torch.isfinite(quats).all(-1)
    pairs = _visible_pairs(p_cam_all.detach(), ks, gaussians_ok, near_plane, far_plane)
    cam_ids, gauss_ids = pairs[:, 0], pairs[:, 1]
    p_cam = p_cam_all.reshape(-1, 3).index_select(0, cam_ids * means.shape[0] + gauss_ids)
    k = ks.index_select(0, cam_ids)
    # The covariance chain runs in float64: det = ac - b^2 cancels catastrophically in float32 for
    # needle-like Gaussians (1000:1 scales), and the extra cost is a few small matrix products. It
    # runs on the visible entries only, so Gaussians culled for non-finite values never enter it.
    f64 = torch.float64
    jac = _jacobians(p_cam.to(f64), k.to(f64), width, height) @ rot.to(f64).index_select(0, cam_ids)
    cov3d = _covariances_3d(quats.index_select(0, gauss_ids).to(f64), scales.index_select(0, gauss_ids).to(f64))
    cov2d = jac @ cov3d @ jac.transpose(1, 2)
    a = cov2d[:, 0, 0] + EPS2D
    b = cov2d[:, 0, 1]
    c = cov2d[:, 1, 1] + EPS2D
    det = a * c - b * b
    z = p_cam[:, 2]
    means2d = torch.stack([k[:, 0, 0] * p_cam[:, 0] / z + k[:, 0, 2], k[:, 1, 1] * p_cam[:, 1] / z + k[:, 1, 2]], -1)
    op = opacities.index_select(0, gauss_ids)
    with torch.no_grad():
        r2 = 2.0 * torch.log(255.0 * op.clamp_min(ALPHA_MIN))
        radii = (torch.sqrt(r2[:, None] * torch.stack([a, c], -1)) * (1.0 + 1e-4) + 1e-3).to(means.dtype)
        rects = _tile_rects(means2d, radii, width, height)
        keep = (det > 0) & torch.isfinite(det) & (rects[:, 0] <= rects[:, 2]) & (rects[:, 1] <= rects[:, 3])
        keep &= torch.isfinite(means2d).all(-1)
        idx = keep.nonzero().squeeze(1)
    # index_select rather than [idx]: its backward is an index_add, not a slower accumulating index_put
    cab = torch.stack([c, -b, a], -1).index_select(0, idx)
    conics = (cab / det.index_select(0, idx)[:, None]).to(means.dtype)
    cam_ids, gauss_ids, p_cam = cam_ids[idx], gauss_ids[idx], p_cam.index_select(0, idx)
    rgb = entry_colors(colors, means, viewmats, cam_ids, gauss_ids, sh_degree)
    return Projection(
        cam_ids=cam_ids,
        gauss_ids=gauss_ids,
        means2d=means2d.index_select(0, idx),
        conics=conics,
        depths=p_cam[:, 2],
        opacities=op.index_select(0, idx),
        colors=with_depth_channel(rgb, p_cam[:, 2], with_depth),
        tile_bbox=rects[idx].contiguous(),
        radii=radii[idx],
    )


def with_depth_channel(rgb: torch.Tensor, depth: torch.Tensor, with_depth: bool) -> torch.Tensor:
    """Append camera-space depth as the last channel, so compositing yields sum T*alpha*z (paper Eq. 2)."""
    return torch.cat([rgb, depth[:, None]], dim=-1) if with_depth else rgb


def entry_colors(
    colors: torch.Tensor,
    means: torch.Tensor,
    viewmats: torch.Tensor,
    cam_ids: torch.Tensor,
    gauss_ids: torch.Tensor,
    sh_degree: int | None,
) -> torch.Tensor:
    """Per-entry colours: given directly (N, D) or evaluated from SH (N, K, 3) for each view direction."""
    if sh_degree is None:
        return colors.index_select(0, gauss_ids)
    if sh_degree == 0:
        return sh0_to_rgb(colors[:, 0]).index_select(0, gauss_ids)
    rot, trans = viewmats[:, :3, :3], viewmats[:, :3, 3]
    centers = -torch.einsum("bji,bj->bi", rot, trans)
    dirs = means.index_select(0, gauss_ids) - centers.index_select(0, cam_ids)
    dirs = dirs / dirs.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    return eval_sh(colors[:, : (sh_degree + 1) ** 2].index_select(0, gauss_ids), dirs, sh_degree)
