"""The CUDA backend: gsplat's kernels (nerfstudio-project/gsplat), when installed and CUDA is present.

gsplat does its own projection; it follows the same conventions (OpenCV cameras, pixel centres at
+0.5, 0.3 px^2 dilation, alpha >= 1/255, alpha <= 0.99, stop at T < 1e-4), and its footprint is the
3-sigma box, so it can differ from the other backends at the faint rims of opaque Gaussians. It runs
packed (one entry per visible pair, as the other backends' projection), so its 2D means carry the
gradients that density control reads.
"""

from __future__ import annotations

import importlib.util

import torch

from .projection import Footprints


def available() -> bool:
    """True when CUDA is usable and gsplat imports."""
    return torch.cuda.is_available() and importlib.util.find_spec("gsplat") is not None


def rasterize(
    means,
    quats,
    scales,
    opacities,
    colors,
    viewmats,
    ks,
    width,
    height,
    *,
    sh_degree,
    near_plane,
    far_plane,
    with_depth,
) -> tuple[torch.Tensor, torch.Tensor, Footprints]:
    """(image (B,H,W,D[+1 depth]), alpha (B,H,W), footprints) rendered by gsplat.rasterization."""
    from gsplat import rasterization

    image, alpha, meta = rasterization(
        means,
        quats,
        scales,
        opacities,
        colors,
        viewmats,
        ks,
        width,
        height,
        near_plane=near_plane,
        far_plane=far_plane,
        sh_degree=sh_degree,
        render_mode="RGB+D" if with_depth else "RGB",
        packed=True,
    )
    footprints = Footprints(
        cam_ids=meta["camera_ids"].long(),
        gauss_ids=meta["gaussian_ids"].long(),
        means2d=meta["means2d"],
        radii=meta["radii"],  # (M, 2) since gsplat 1.5
    )
    return image, alpha[..., 0], footprints
