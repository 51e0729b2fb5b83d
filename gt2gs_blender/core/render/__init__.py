"""One differentiable rasterizer entry point over swappable backends (the shape of gsplat's API).

``rasterization()`` renders colour, expected depth (paper Eq. 2: D = sum_i T_i alpha_i z_i) and alpha
for a batch of same-size cameras. Alpha rules, identical in every backend: a Gaussian's footprint
is where alpha = opacity * exp(-d^T Sigma^-1 d / 2) >= 1/255 (with 0.3 px^2 dilation of Sigma);
alpha is clamped to 0.99; a pixel stops before the Gaussian that would bring its transmittance
below 1e-4. Backends: ``cpu`` (C++/OpenMP kernel, compiled at first use), ``numba`` (the same kernel
ported to numba: as fast, no compiler needed), ``torch`` (portable, CPU or CUDA), ``gsplat`` (CUDA
kernels when installed). ``fix_geometry()`` records a render's compositing weights, so that
while the geometry holds still any colours are redrawn as a weighted gather (``fixed_geometry``).
"""

from __future__ import annotations

from collections.abc import Sequence

import torch

from ..cameras.camera import Camera, stack_cameras
from ..scene.gaussians import GaussianScene
from . import cpu_backend, gsplat_backend, torch_backend
from .backends import BACKENDS, available_backends, kernel, resolve_backend
from .fixed_geometry import FixedGeometry, fix_geometry
from .output import RenderOutput
from .projection import FAR_PLANE, NEAR_PLANE, project

__all__ = [
    "BACKENDS",
    "FixedGeometry",
    "RenderOutput",
    "available_backends",
    "fix_geometry",
    "rasterization",
    "render",
    "resolve_backend",
]


def rasterization(
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
    sh_degree: int | None = None,
    near_plane: float = NEAR_PLANE,
    far_plane: float = FAR_PLANE,
    backgrounds: torch.Tensor | None = None,
    render_depth: bool = True,
    backend: str = "auto",
) -> RenderOutput:
    """Render N Gaussians into B cameras.

    Gaussians: means (N,3), quats (N,4) w-first (normalised here), activated scales (N,3) and
    opacities (N,). ``colors`` is (N,D) when ``sh_degree`` is None, else SH coefficients (N,K,3)
    evaluated up to ``sh_degree`` from each camera. Cameras: world-to-camera ``viewmats`` (B,4,4)
    in the OpenCV frame and intrinsics ``ks`` (B,3,3). ``backgrounds`` (B,D) or (D,) is added
    where the render is transparent. Differentiable w.r.t. every Gaussian input.
    """
    name = resolve_backend(backend, means.device)
    n_cams = viewmats.shape[0]
    inputs = (means, quats, scales, opacities, colors, viewmats, ks, width, height)
    options = {"sh_degree": sh_degree, "near_plane": near_plane, "far_plane": far_plane, "with_depth": render_depth}
    if name == "gsplat":
        image, alpha, footprints = gsplat_backend.rasterize(*inputs, **options)
    elif name == "torch":
        proj = project(*inputs, **options)
        image, alpha = torch_backend.composite(proj, n_cams, width, height)
        footprints = proj.footprints()
    else:  # a compiled kernel: C++ or numba
        compiled = kernel(name)
        proj = cpu_backend.project(*inputs, **options, kernel=compiled)
        image, alpha = cpu_backend.composite(proj, n_cams, width, height, kernel=compiled)
        footprints = proj.footprints()
    rgb, depth = (image[..., :-1], image[..., -1]) if render_depth else (image, None)
    if backgrounds is not None:
        bg = backgrounds.reshape(-1, 1, 1, rgb.shape[-1]) if backgrounds.dim() == 2 else backgrounds
        rgb = rgb + (1.0 - alpha[..., None]) * bg
    return RenderOutput(colors=rgb, depths=depth, alphas=alpha, backend=name, footprints=footprints)


def render(
    scene: GaussianScene,
    cameras: Sequence[Camera],
    *,
    colors: torch.Tensor | None = None,
    background: Sequence[float] | torch.Tensor | None = None,
    render_depth: bool = True,
    backend: str = "auto",
    sh_degree: int | None = None,
) -> RenderOutput:
    """Render a scene's activated parameters into same-size cameras.

    ``colors`` (N,D) overrides the SH colours (used to render the geometry-preservation colours);
    ``sh_degree`` may lower the scene's degree (bands above it are never evaluated).
    """
    viewmats, ks, width, height = stack_cameras(cameras, device=scene.device, dtype=scene.dtype)
    if colors is None:
        degree = scene.sh_degree if sh_degree is None else min(sh_degree, scene.sh_degree)
        colors_in, degree_in = scene.sh, degree
    else:
        colors_in, degree_in = colors, None
    bg = None
    if background is not None:
        bg = torch.as_tensor(background, dtype=scene.dtype, device=scene.device)
    return rasterization(
        scene.means,
        scene.quats,
        scene.scales,
        scene.opacities,
        colors_in,
        viewmats,
        ks,
        width,
        height,
        sh_degree=degree_in,
        backgrounds=bg,
        render_depth=render_depth,
        backend=backend,
    )
