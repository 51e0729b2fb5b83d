"""One differentiable rasterizer entry point over swappable backends (the shape of gsplat's API).

``rasterization()`` renders colour, expected depth (paper Eq. 2: D = sum_i T_i alpha_i z_i) and alpha
for a batch of same-size cameras. Alpha rules, identical in every backend: a Gaussian's footprint
is where alpha = opacity * exp(-d^T Sigma^-1 d / 2) >= 1/255 (with 0.3 px^2 dilation of Sigma);
alpha is clamped to 0.99; a pixel stops before the Gaussian that would bring its transmittance
below 1e-4. Backends: ``cpu`` (C++/OpenMP kernel), ``torch`` (portable, CPU or CUDA), ``gsplat``
(CUDA kernels when installed).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass

import torch

from ..cameras.camera import Camera, stack_cameras
from ..scene.gaussians import GaussianScene
from . import cpu_backend, gsplat_backend, torch_backend
from .projection import Footprints, project

BACKENDS = ("torch", "cpu", "gsplat")
log = logging.getLogger(__name__)


@dataclass
class RenderOutput:
    """Renders of B cameras. ``footprints`` holds the visible (camera, Gaussian) entries with their
    differentiable 2D means and extents (for densification statistics), from every backend."""

    colors: torch.Tensor  # (B, H, W, D) composited over the background
    depths: torch.Tensor | None  # (B, H, W) expected depth sum T*alpha*z (not divided by alpha)
    alphas: torch.Tensor  # (B, H, W)
    backend: str
    footprints: Footprints


def available_backends(device: torch.device | str = "cpu") -> list[str]:
    """Backends that can render on ``device`` here, fastest first."""
    device = torch.device(device)
    if device.type == "cuda":
        return (["gsplat"] if gsplat_backend.available() else []) + ["torch"]
    return (["cpu"] if cpu_backend.load_kernel() is not None else []) + ["torch"]


def resolve_backend(backend: str, device: torch.device | str) -> str:
    """The backend that will run: ``auto`` picks the fastest; an unavailable choice falls back, logged."""
    if backend != "auto" and backend not in BACKENDS:
        raise ValueError(f"unknown rasterizer backend {backend!r}; choose one of auto, {', '.join(BACKENDS)}")
    if backend == "torch":  # always usable; never pay for building the C++ kernel
        return backend
    usable = available_backends(device)
    if backend == "auto":
        return usable[0]
    if backend not in usable:
        reason = cpu_backend.unavailable_reason() if backend == "cpu" else f"not usable on {torch.device(device)}"
        log.warning("rasterizer backend %r unavailable (%s); using %r", backend, reason, usable[0])
        return usable[0]
    return backend


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
    near_plane: float = 0.01,
    far_plane: float = 1e10,
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
    else:
        backend_module = cpu_backend if name == "cpu" else torch_backend
        projector = cpu_backend.project if name == "cpu" else project
        proj = projector(*inputs, **options)
        image, alpha = backend_module.composite(proj, n_cams, width, height)
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
