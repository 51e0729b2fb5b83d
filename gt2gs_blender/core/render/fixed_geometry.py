"""Renders of fixed geometry as a linear map of the colours: colour-only steps at the cost of a gather.

While the means, shapes and opacities stay put, each pixel of a render is sum_i w_i c_i + T bg, with
w_i = alpha_i T_i the compositing weight of the i-th Gaussian in front of it (the alpha rules of
:func:`rasterization`). :func:`fix_geometry` records those weights once per camera (the CPU kernel's
forward sweep, C++ or numba) and :meth:`FixedGeometry.render` then renders any colours, and their gradient, as a
weighted gather and scatter: the projection, depth sort, tile binning and both compositing sweeps of
a render are skipped. The same sums in the same order as the kernel's forward: given its colours the
image is the rasterizer's to the bit; the SH colours are evaluated here by torch (within float rounding
of the kernel's), and the colour gradient is summed in another order.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import torch

from ..cameras.camera import Camera, stack_cameras
from ..scene.gaussians import GaussianScene
from . import cpu_backend
from .backends import KERNEL_BACKENDS, kernel, resolve_backend
from .output import RenderOutput
from .projection import FAR_PLANE, NEAR_PLANE, Footprints, entry_colors


@dataclass
class FixedGeometry:
    """One camera batch's compositing weights for a scene whose geometry does not change.

    ``offsets`` (B*H*W+1,) int64 are CSR rows over the pixels in image order, ``entries`` (nnz,) int32
    the visible (camera, Gaussian) entry of each weight, ``weights`` (nnz,) the weights."""

    offsets: torch.Tensor
    entries: torch.Tensor
    weights: torch.Tensor
    alphas: torch.Tensor  # (B, H, W)
    footprints: Footprints  # the entries (detached), for density statistics
    means: torch.Tensor  # (N, 3) detached: the view directions of SH colours
    viewmats: torch.Tensor  # (B, 4, 4)
    n_gaussians: int
    backend: str  # the kernel backend that recorded them and redraws from them

    @property
    def nbytes(self) -> int:
        """Memory held by the recorded weights."""
        return sum(t.numel() * t.element_size() for t in (self.offsets, self.entries, self.weights))

    def render(self, scene: GaussianScene, *, background: torch.Tensor | None = None):
        """The scene's SH colours through the recorded weights: a :class:`RenderOutput` without depth,
        differentiable w.r.t. the colours only (the geometry is the recorded one)."""
        if len(scene) != self.n_gaussians:
            raise ValueError(f"fixed geometry of {self.n_gaussians} Gaussians used for a scene of {len(scene)}")
        fp = self.footprints
        colors = entry_colors(scene.sh, self.means, self.viewmats, fp.cam_ids, fp.gauss_ids, scene.sh_degree)
        args = (colors, self.offsets, self.entries, self.weights, kernel(self.backend))
        rgb = _WeightedRows.apply(*args).reshape(*self.alphas.shape, -1)
        if background is not None:
            rgb = rgb + (1.0 - self.alphas[..., None]) * background.reshape(-1, 1, 1, rgb.shape[-1])
        return RenderOutput(colors=rgb, depths=None, alphas=self.alphas, backend=self.backend, footprints=fp)


class _WeightedRows(torch.autograd.Function):
    @staticmethod
    def forward(ctx, values, offsets, entries, weights, compiled):
        ctx.save_for_backward(offsets, entries, weights)
        ctx.n_values, ctx.kernel = values.shape[0], compiled
        return compiled.weighted_rows(offsets, entries, weights, values)

    @staticmethod
    def backward(ctx, grad):
        offsets, entries, weights = ctx.saved_tensors
        grad_values = ctx.kernel.weighted_rows_backward(offsets, entries, weights, grad, ctx.n_values)
        return grad_values, None, None, None, None


def fix_geometry(scene: GaussianScene, cameras: Sequence[Camera], *, backend: str = "auto") -> FixedGeometry | None:
    """Record the compositing weights of ``scene`` in ``cameras``; None where only a CPU kernel (C++ or
    numba) can (another backend chosen, a GPU scene, float64, or no kernel available): render normally then."""
    name = resolve_backend(backend, scene.device)
    if scene.dtype != torch.float32 or name not in KERNEL_BACKENDS:
        return None
    compiled = kernel(name)
    viewmats, ks, width, height = stack_cameras(cameras, device=scene.device, dtype=scene.dtype)
    with torch.no_grad():
        means, opacities = scene.means.detach(), scene.opacities.detach()
        proj = cpu_backend.project(
            means,
            scene.quats.detach(),
            scene.scales.detach(),
            opacities,
            opacities[:, None],  # any one channel: the weights do not depend on the colours
            viewmats,
            ks,
            width,
            height,
            sh_degree=None,
            near_plane=NEAR_PLANE,
            far_plane=FAR_PLANE,
            with_depth=False,
            kernel=compiled,
        )
        bins = cpu_backend.bin_entries(proj, len(cameras), width, height, compiled)
        offsets, entries, weights, final_t = compiled.contributions(
            proj.means2d.contiguous(),
            proj.conics.contiguous(),
            proj.opacities.contiguous(),
            bins.offsets,
            bins.pair_gauss,
            len(cameras),
            width,
            height,
        )
    return FixedGeometry(
        offsets=offsets,
        entries=entries,
        weights=weights,
        alphas=1.0 - final_t,
        footprints=proj.footprints(),
        means=means,
        viewmats=viewmats,
        n_gaussians=len(scene),
        backend=name,
    )
