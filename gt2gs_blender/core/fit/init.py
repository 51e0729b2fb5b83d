"""Initial Gaussians for a fit: from a coloured point cloud, or random points inside the views.

As in 3DGS, each point becomes an isotropic Gaussian whose size is the root-mean-square distance to
its 3 nearest neighbours (so the cloud starts without holes or heavy overlap), with opacity 0.1.
Without a point cloud, points are drawn inside the cameras' viewing frusta between the near and far
bounds, uniformly in disparity (1/depth): forward-facing captures such as LLFF span a large depth
range, and uniform-in-disparity puts as many points per pixel of parallax near as far. Their sizes
come from their spacing on screen instead (see :func:`frustum_points`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch

from ..cameras.camera import Camera
from ..scene.gaussians import GaussianScene

INIT_OPACITY = 0.1
KNN_CHUNK_ELEMENTS = 2**24
"""Distances computed per chunk of query points (64 MiB of float32), so memory stays bounded."""


def knn_scales(points: torch.Tensor, k: int = 3) -> torch.Tensor:
    """RMS distance (N,) from each point to its ``k`` nearest other points (chunked, exact)."""
    n = points.shape[0]
    if n <= k:
        raise ValueError(f"need more than {k} points to size Gaussians by their {k} nearest neighbours, got {n}")
    chunk = max(1, KNN_CHUNK_ELEMENTS // n)
    out = []
    for start in range(0, n, chunk):
        queries = points[start : start + chunk]
        d2 = torch.cdist(queries, points).square_()
        d2[torch.arange(len(queries)), torch.arange(start, start + len(queries))] = torch.inf
        out.append(d2.topk(k, dim=1, largest=False).values.mean(dim=1))
    return torch.cat(out).clamp_min(1e-14).sqrt()


def scene_from_points(
    points: torch.Tensor,
    colors: torch.Tensor,
    *,
    scales: torch.Tensor | None = None,
    sh_degree: int = 0,
    opacity: float = INIT_OPACITY,
) -> GaussianScene:
    """Isotropic Gaussians at ``points`` (N,3) with RGB ``colors`` (N,3) in [0,1], of size ``scales``
    (N,) or, by default, sized by their 3 nearest neighbours."""
    n = points.shape[0]
    scales = (knn_scales(points) if scales is None else scales)[:, None].expand(n, 3)
    opacities = torch.full((n,), opacity, dtype=points.dtype, device=points.device)
    return GaussianScene.from_activated(points, scales.contiguous(), opacities, colors, sh_degree=sh_degree)


def frustum_points(
    cameras: Sequence[Camera],
    near: Sequence[float],
    far: Sequence[float],
    count: int,
    *,
    images: torch.Tensor | None = None,
    generator: torch.Generator | None = None,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """``count`` random points (float32) seen by the cameras, each on the ray of a random pixel of a
    random view at a depth uniform in disparity between that view's ``near`` and ``far``.

    Returns points, colours (that pixel's colour in ``images`` (V,H,W,3) when given, else mid grey)
    and sizes: the points' mean spacing *on screen*, sqrt(pixels / count), at their depth. In a
    volume, 3-NN sizes would make every pixel see hundreds of large Gaussians, which costs a CPU
    rasterizer dearly and adds nothing that densification does not add later."""
    if not (len(cameras) == len(near) == len(far)) or not cameras:
        raise ValueError("frustum_points needs one near and one far bound per camera, and a camera")
    view = torch.randint(len(cameras), (count,), generator=generator)
    u, v, t = torch.rand(3, count, generator=generator, dtype=torch.float64)
    params = torch.tensor(
        [[c.width, c.height, c.fx, c.fy, c.cx, c.cy, 1.0 / f, 1.0 / n] for c, n, f in zip(cameras, near, far)],
        dtype=torch.float64,
    )[view]
    width, height, fx, fy, cx, cy, disp_far, disp_near = params.unbind(-1)
    px, py = u * width, v * height
    depth = 1.0 / (disp_far + t * (disp_near - disp_far))
    cam_pts = torch.stack([(px - cx) / fx * depth, (py - cy) / fy * depth, depth], dim=-1)
    c2w = torch.tensor(np.stack([c.cam_to_world for c in cameras]), dtype=torch.float64)[view]
    world = (c2w[:, :3, :3] @ cam_pts[..., None])[..., 0] + c2w[:, :3, 3]
    if images is None:
        colors = torch.full((count, 3), 0.5)
    else:
        colors = images[view, py.long().clamp(max=images.shape[1] - 1), px.long().clamp(max=images.shape[2] - 1)]
    spacing_px = torch.sqrt(width * height / count)
    return world.float(), colors.float(), (spacing_px * depth / torch.sqrt(fx * fy)).float()
