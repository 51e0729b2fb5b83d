"""The fast CPU backends: a small C++/OpenMP kernel, compiled once per content (see kernel_cache), and the
autograd glue every kernel with its functions shares (the C++ one, or numba_backend's port of it)."""

from __future__ import annotations

import logging
import threading
from types import ModuleType
from typing import Any

import torch

from ..errors import GT2GSError
from . import kernel_cache
from .binning import TileBins
from .projection import Projection, tile_grid, with_depth_channel

TOO_MANY_PAIRS = "too many Gaussian/tile pairs for one render"
"""How both kernels (csrc/raster_cpu.cpp, numba_kernel.py) say a render passed their 2^31 splat/tile pairs."""
log = logging.getLogger(__name__)
_lock = threading.Lock()
_state: dict[str, object] = {}


def load_kernel() -> ModuleType | None:
    """Compile (first time) and import the kernel; None, with the reason logged, if that fails."""
    with _lock:
        if "module" not in _state:
            _state["module"], _state["reason"] = _compile()
            if _state["module"] is None:
                log.warning("fast CPU rasterizer unavailable (the C++ kernel did not build): %s", _state["reason"])
        return _state["module"]  # type: ignore[return-value]


def unavailable_reason() -> str | None:
    """Why the kernel could not be built, or None when it is available."""
    load_kernel()
    return _state.get("reason")  # type: ignore[return-value]


def _compile() -> tuple[ModuleType | None, str | None]:
    """The kernel from its content-keyed cache (see kernel_cache), or None and why not."""
    try:
        return kernel_cache.load(), None
    except Exception as exc:  # compiler, ninja or headers missing: fall back, never fail the render
        return None, f"{type(exc).__name__}: {str(exc).strip().splitlines()[-1] if str(exc).strip() else exc}"


def depth_order(depths: torch.Tensor, kernel: Any = None) -> torch.Tensor:
    """Entry indices front to back, ties by index: the kernel's radix sort for float32 (linear, the argsort
    was a tenth of a transfer's time), a stable argsort for float64. ``kernel``: the C++ one when None."""
    if depths.dtype == torch.float32:
        return (kernel or load_kernel()).depth_order(depths.contiguous())
    return torch.argsort(depths, stable=True)


def bin_entries(proj: Projection, n_cams: int, width: int, height: int, kernel: Any = None) -> TileBins:
    """Counting-sort binning in the kernel (linear in the number of pairs)."""
    kernel = kernel or load_kernel()
    tiles_x, tiles_y = tile_grid(width, height)
    order = depth_order(proj.depths.detach(), kernel)
    try:
        offsets, pairs = kernel.bin_tiles(proj.tile_bbox, proj.cam_ids.to(torch.int32), order, n_cams, tiles_x, tiles_y)
    except (RuntimeError, ValueError) as exc:
        if TOO_MANY_PAIRS not in str(exc):
            raise
        size = f"{n_cams} view{'s' if n_cams > 1 else ''} of {width}x{height} px"
        raise GT2GSError(
            f"the render is too large for the rasterizer ({size}: over 2^31 splat/tile pairs); render smaller or "
            "fewer views at once"
        ) from None
    return TileBins(offsets=offsets, pair_gauss=pairs)


class _Composite(torch.autograd.Function):
    @staticmethod
    def forward(ctx, means2d, conics, colors, opacities, bins: TileBins, n_cams: int, width: int, height: int, kernel):
        ctx.kernel = kernel
        args = (means2d.contiguous(), conics.contiguous(), colors.contiguous(), opacities.contiguous())
        image, final_t, pixel_end = kernel.forward(*args, bins.offsets, bins.pair_gauss, n_cams, width, height)
        ctx.save_for_backward(*args, bins.offsets, bins.pair_gauss, final_t, pixel_end)
        ctx.shape = (n_cams, width, height)
        ctx.mark_non_differentiable(pixel_end)
        return image, 1.0 - final_t

    @staticmethod
    def backward(ctx, grad_image, grad_alpha):
        means2d, conics, colors, opacities, offsets, pairs, final_t, pixel_end = ctx.saved_tensors
        n_cams, width, height = ctx.shape
        if grad_image is None:
            grad_image = colors.new_zeros(n_cams, height, width, colors.shape[1])
        if grad_alpha is None:
            grad_alpha = torch.zeros_like(final_t)
        geometry = ctx.needs_input_grad[0] or ctx.needs_input_grad[1] or ctx.needs_input_grad[3]
        g_means, g_conics, g_colors, g_op = ctx.kernel.backward(
            means2d,
            conics,
            colors,
            opacities,
            offsets,
            pairs,
            final_t,
            pixel_end,
            grad_image,
            grad_alpha,
            n_cams,
            width,
            height,
            geometry,
        )
        return g_means, g_conics, g_colors, g_op, None, None, None, None, None


def composite(
    proj: Projection, n_cams: int, width: int, height: int, kernel: Any = None
) -> tuple[torch.Tensor, torch.Tensor]:
    """(image (B,H,W,D), alpha (B,H,W)) of the projected entries, by ``kernel`` (the C++ one when None)."""
    kernel = kernel or load_kernel()
    bins = bin_entries(proj, n_cams, width, height, kernel)
    args = (proj.means2d, proj.conics, proj.colors, proj.opacities, bins, n_cams, width, height, kernel)
    return _Composite.apply(*args)


class _Project(torch.autograd.Function):
    """C++ projection of the visible entries (compacted in the kernel); gradients flow to the Gaussians."""

    @staticmethod
    def forward(ctx, means, quats, scales, opacities, sh, viewmats, ks, width, height, near, far, sh_degree, kernel):
        ctx.kernel = kernel
        sh_in = sh if sh_degree >= 0 else means.new_zeros(0)
        means2d, conics, rgb, depth, radii, rects, cam_ids, gauss_ids = kernel.project_forward(
            means.detach(),
            quats.detach(),
            scales.detach(),
            opacities.detach(),
            sh_in.detach(),
            viewmats,
            ks,
            width,
            height,
            near,
            far,
            sh_degree,
        )
        ctx.save_for_backward(means, quats, scales, sh_in, viewmats, ks, cam_ids, gauss_ids)
        ctx.config = (width, height, sh_degree)
        ctx.mark_non_differentiable(cam_ids, gauss_ids, radii, rects)
        return means2d, conics, rgb, depth, cam_ids, gauss_ids, radii, rects

    @staticmethod
    def backward(ctx, g_means2d, g_conics, g_rgb, g_depth, *_):
        means, quats, scales, sh_in, viewmats, ks, cam_ids, gauss_ids = ctx.saved_tensors
        width, height, sh_degree = ctx.config
        m = cam_ids.shape[0]
        zeros = {"m2": (m, 2), "con": (m, 3), "rgb": (m, 3 if sh_degree >= 0 else 0), "d": (m,)}
        g_means2d = means.new_zeros(zeros["m2"]) if g_means2d is None else g_means2d
        g_conics = means.new_zeros(zeros["con"]) if g_conics is None else g_conics
        g_rgb = means.new_zeros(zeros["rgb"]) if g_rgb is None else g_rgb
        g_depth = means.new_zeros(zeros["d"]) if g_depth is None else g_depth
        geometry = any(ctx.needs_input_grad[:3])  # means, quats, scales: else a colour-only step
        gm, gq, gs, gsh = ctx.kernel.project_backward(
            means.detach(),
            quats.detach(),
            scales.detach(),
            sh_in.detach(),
            viewmats,
            ks,
            width,
            height,
            sh_degree,
            cam_ids,
            gauss_ids,
            g_means2d,
            g_conics,
            g_rgb,
            g_depth,
            geometry,
        )
        gm, gq, gs = (gm, gq, gs) if geometry else (None, None, None)
        return gm, gq, gs, None, gsh if sh_degree >= 0 else None, None, None, None, None, None, None, None, None


def project(
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
    kernel: Any = None,
) -> Projection:
    """The kernel's twin of projection.project (same entries, same rules); ``kernel``: the C++ one when None."""
    degree = -1 if sh_degree is None else sh_degree
    means2d, conics, rgb, depth, cam_ids, gauss_ids, radii, rects = _Project.apply(
        means,
        quats,
        scales,
        opacities,
        colors,
        viewmats.detach(),
        ks.detach(),
        width,
        height,
        near_plane,
        far_plane,
        degree,
        kernel or load_kernel(),
    )
    if sh_degree is None:
        rgb = colors[gauss_ids]
    if not (means.requires_grad or quats.requires_grad or scales.requires_grad):
        # the projected geometry does not depend on the colours: a colour-only step's compositing skips it
        means2d, conics, depth = means2d.detach(), conics.detach(), depth.detach()
    return Projection(
        cam_ids=cam_ids,
        gauss_ids=gauss_ids,
        means2d=means2d,
        conics=conics,
        depths=depth,
        opacities=opacities[gauss_ids],
        colors=with_depth_channel(rgb, depth, with_depth),
        tile_bbox=rects,
        radii=radii,
    )
