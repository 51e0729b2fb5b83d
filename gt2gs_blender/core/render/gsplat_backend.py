"""The CUDA backend: gsplat's kernels (nerfstudio-project/gsplat), when installed and CUDA is present.

gsplat does its own projection; it follows the same conventions (OpenCV cameras, pixel centres at
+0.5, 0.3 px^2 dilation, alpha >= 1/255, alpha <= 0.99, stop at T < 1e-4), and its footprint is the
3-sigma box, so it can differ from the other backends at the faint rims of opaque Gaussians.
"""

from __future__ import annotations

import importlib.util

import torch


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
) -> tuple[torch.Tensor, torch.Tensor]:
    """(image (B,H,W,D[+1 depth]), alpha (B,H,W)) rendered by gsplat.rasterization."""
    from gsplat import rasterization

    image, alpha, _ = rasterization(
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
        packed=False,
    )
    return image, alpha[..., 0]
