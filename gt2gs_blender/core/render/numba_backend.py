"""The fast CPU backend without a C++ compiler: the kernel ported to numba (numba_kernel), JIT-compiled once.

:func:`load_kernel` returns an object with the compiled kernel's functions, arguments and results (torch
tensors in and out, shared with numpy without copies), so cpu_backend's autograd glue and fixed_geometry
run either kernel. numba caches the machine code on disk (in ``<kernel cache>/numba``); :func:`warm_up`
compiles every function a float32 run needs, once, and leaves a marker, so the first run can show the JIT
as a stage of its own and later runs know it is done (:func:`is_compiled`).
"""

from __future__ import annotations

import hashlib
import logging
import os
import threading
from pathlib import Path
from types import ModuleType

import numpy as np
import torch

from . import kernel_cache

log = logging.getLogger(__name__)
_lock = threading.Lock()
_state: dict[str, object] = {}
SOURCE = Path(__file__).with_name("numba_kernel.py")


def cache_dir() -> Path:
    """Where numba keeps the compiled kernel: ``NUMBA_CACHE_DIR`` when set, else beside the C++ builds."""
    return Path(os.environ.get("NUMBA_CACHE_DIR") or kernel_cache.cache_base() / "numba")


def _marker() -> Path:
    """The file a finished warm-up leaves: named by numba's version and the kernel source's bytes."""
    import importlib.metadata

    digest = hashlib.sha256(SOURCE.read_bytes())
    digest.update(importlib.metadata.version("numba").encode())
    return cache_dir() / f"warm-{digest.hexdigest()[:16]}"


def installed() -> bool:
    """Whether numba can be imported here (without importing it)."""
    import importlib.util

    return importlib.util.find_spec("numba") is not None


def is_compiled() -> bool:
    """Whether the numba kernel was compiled and cached here already (so a run starts without the JIT)."""
    return installed() and _marker().is_file()


def load_kernel() -> NumbaKernel | None:
    """The numba kernel (imported once; functions compile on first call); None, with the reason logged,
    when numba is not installed or fails to import."""
    with _lock:
        if "kernel" not in _state:
            _state["kernel"], _state["reason"] = _import()
            if _state["kernel"] is None:
                log.warning("numba rasterizer unavailable: %s", _state["reason"])
        return _state["kernel"]  # type: ignore[return-value]


def unavailable_reason() -> str | None:
    """Why the numba kernel cannot run, or None when it can."""
    load_kernel()
    return _state.get("reason")  # type: ignore[return-value]


def _import() -> tuple[NumbaKernel | None, str | None]:
    """The kernel module imported under this package's cache folder, or None and why not."""
    os.environ.setdefault("NUMBA_CACHE_DIR", str(cache_dir()))
    try:
        from . import numba_kernel
    except Exception as exc:  # numba missing, or built for another numpy: fall back, never fail the render
        return None, f"{type(exc).__name__}: {str(exc).strip().splitlines()[-1] if str(exc).strip() else exc}"
    return NumbaKernel(numba_kernel), None


def warm_up() -> None:
    """Compile (or load from numba's cache) everything a float32 run calls, by rendering a tiny scene
    (full and colour-only steps, forward and backward, and from recorded weights); then leave the marker
    :func:`is_compiled` reads."""
    from . import cpu_backend
    from .projection import FAR_PLANE, NEAR_PLANE

    kernel = load_kernel()
    if kernel is None:
        return
    g = torch.Generator().manual_seed(0)
    n, width, height = 64, 32, 24
    means = (torch.rand(n, 3, generator=g) - 0.5) * 0.5
    quats = torch.randn(n, 4, generator=g)
    scales = torch.full((n, 3), 0.05)
    opacities = torch.full((n,), 0.7)
    sh = torch.randn(n, 16, 3, generator=g) * 0.3
    viewmats = torch.eye(4)[None].clone()
    viewmats[0, 2, 3] = 3.0
    ks = torch.tensor([[[40.0, 0.0, 16.0], [0.0, 40.0, 12.0], [0.0, 0.0, 1.0]]])
    options = {"near_plane": NEAR_PLANE, "far_plane": FAR_PLANE, "with_depth": True, "kernel": kernel}
    for degree, geometry in ((3, True), (3, False), (None, True)):
        params = [t.clone().requires_grad_(geometry) for t in (means, quats, scales, opacities)]
        colors = (sh if degree is not None else sh[:, 0]).clone().requires_grad_(True)
        proj = cpu_backend.project(*params, colors, viewmats, ks, width, height, sh_degree=degree, **options)
        image, alpha = cpu_backend.composite(proj, 1, width, height, kernel=kernel)
        (image.sum() + alpha.sum()).backward()
    bins = cpu_backend.bin_entries(proj, 1, width, height, kernel=kernel)
    offsets, entries, weights, _ = kernel.contributions(
        proj.means2d.detach(), proj.conics.detach(), proj.opacities.detach(), bins.offsets, bins.pair_gauss, 1,
        width, height,
    )  # fmt: skip
    image = kernel.weighted_rows(offsets, entries, weights, proj.colors.detach())
    kernel.weighted_rows_backward(offsets, entries, weights, image, proj.colors.shape[0])
    marker = _marker()
    marker.parent.mkdir(parents=True, exist_ok=True)
    kernel_cache.write_atomically(marker, b"")


def _np(t: torch.Tensor) -> np.ndarray:
    """A tensor's numpy view (contiguous, detached)."""
    return t.detach().contiguous().numpy()


class NumbaKernel:
    """The C++ kernel's functions over the numba ones (see csrc/raster_cpu.cpp for each one's contract)."""

    def __init__(self, module: ModuleType):
        self.k = module

    def _threads(self) -> int:
        """Use torch's thread count (the user's Threads setting), as the C++ kernel does."""
        import numba

        threads = max(1, min(torch.get_num_threads(), numba.config.NUMBA_NUM_THREADS))
        numba.set_num_threads(threads)
        return threads

    def depth_order(self, depths: torch.Tensor) -> torch.Tensor:
        return torch.from_numpy(self.k.depth_order(_np(depths)))

    def bin_tiles(self, tile_bbox, cam_ids, order, n_cams: int, tiles_x: int, tiles_y: int):
        runs = min(self._threads(), max(1, tile_bbox.shape[0] // 4096))
        offsets, pairs = self.k.bin_tiles(_np(tile_bbox), _np(cam_ids), _np(order), n_cams, tiles_x, tiles_y, runs)
        return torch.from_numpy(offsets), torch.from_numpy(pairs)

    def _sweep(self, means2d, conics, colors, opacities, offsets, pairs, n_cams, width, height, mode, row_ptr):
        """Run the forward sweep (mode 0 colours, 1 count weights, 2 write them); (colour, T, end, ent, w)."""
        units = self._threads() * self.k.UNITS_PER_THREAD
        dtype = _np(means2d).dtype
        n_pix = n_cams * height * width
        color = np.zeros((n_pix if mode == 0 else 0, colors.shape[1]), dtype)
        final_t = np.ones(n_pix, dtype)
        end = np.zeros(n_pix, np.int32)
        nnz = int(row_ptr[-1]) if mode == 2 else 0
        ent, weights = np.empty(nnz, np.int32), np.empty(nnz, dtype)
        cursor = row_ptr[:-1].copy() if mode == 2 else row_ptr
        args = (_np(means2d), _np(conics), _np(opacities), _np(colors), _np(offsets), _np(pairs))
        foot = self.k.footprints(args[1], args[2])
        consts = self.k._constants(dtype)
        self.k.sweep(*args, foot, units, n_cams, width, height, consts, mode, color, final_t, end, cursor, ent, weights)
        return color, final_t, end, ent, weights

    def forward(self, means2d, conics, colors, opacities, offsets, pairs, n_cams: int, width: int, height: int):
        row_ptr = np.zeros(1, np.int64)
        color, final_t, end, _, _ = self._sweep(
            means2d, conics, colors, opacities, offsets, pairs, n_cams, width, height, 0, row_ptr
        )
        shape = (n_cams, height, width)
        return (
            torch.from_numpy(color).reshape(*shape, -1),
            torch.from_numpy(final_t).reshape(shape),
            torch.from_numpy(end).reshape(shape),
        )

    def contributions(self, means2d, conics, opacities, offsets, pairs, n_cams: int, width: int, height: int):
        row_ptr = np.zeros(n_cams * height * width + 1, np.int64)
        none = opacities.new_empty(opacities.shape[0], 1)
        args = (means2d, conics, none, opacities, offsets, pairs, n_cams, width, height)
        self._sweep(*args, 1, row_ptr)
        np.cumsum(row_ptr, out=row_ptr)
        _, final_t, _, ent, weights = self._sweep(*args, 2, row_ptr)
        tensors = (row_ptr, ent, weights)
        return (*(torch.from_numpy(t) for t in tensors), torch.from_numpy(final_t).reshape(n_cams, height, width))

    def backward(self, means2d, conics, colors, opacities, offsets, pairs, final_t, pixel_end, grad_image,
                 grad_alpha, n_cams: int, width: int, height: int, geometry: bool):  # fmt: skip
        units = self._threads()
        dtype = _np(means2d).dtype
        n_ch = colors.shape[1]
        foot = self.k.footprints(_np(conics), _np(opacities))
        total = self.k.backward(
            _np(means2d), _np(conics), _np(colors), _np(opacities), _np(offsets), _np(pairs), foot, units,
            _np(final_t).reshape(-1), _np(pixel_end).reshape(-1), _np(grad_image.to(means2d.dtype)).reshape(-1, n_ch),
            _np(grad_alpha.to(means2d.dtype)).reshape(-1), n_cams, width, height, self.k._constants(dtype), geometry,
        )  # fmt: skip
        total = torch.from_numpy(total)
        return (
            total[:, 0:2].contiguous(),
            total[:, 2:5].contiguous(),
            total[:, 6:].contiguous(),
            total[:, 5].contiguous(),
        )

    def weighted_rows(self, offsets, entries, weights, values):
        self._threads()
        out = np.empty((offsets.shape[0] - 1, values.shape[1]), _np(values).dtype)
        self.k.weighted_rows(_np(offsets), _np(entries), _np(weights), _np(values), out)
        return torch.from_numpy(out)

    def weighted_rows_backward(self, offsets, entries, weights, grad, n_values: int):
        units = self._threads()
        grad = _np(grad.to(weights.dtype))
        args = (_np(offsets), _np(entries), _np(weights), grad, n_values, units)
        return torch.from_numpy(self.k.weighted_rows_backward(*args))

    def project_forward(self, means, quats, scales, opacities, sh, viewmats, ks, width, height, near, far, sh_degree):
        self._threads()
        if sh_degree > 3:
            raise ValueError("SH degree must be at most 3")
        n_cams, n = viewmats.shape[0], means.shape[0]
        dtype = _np(means).dtype
        dense = (
            np.empty((n_cams, n, 2), dtype),
            np.empty((n_cams, n, 3), dtype),
            np.empty((n_cams, n, 3 if sh_degree >= 0 else 0), dtype),
            np.empty((n_cams, n), dtype),
            np.empty((n_cams, n, 2), dtype),
            np.empty((n_cams, n, 4), np.int32),
            np.empty((n_cams, n), np.bool_),
        )
        sh_in = _np(sh) if sh_degree >= 0 else np.zeros((0, 1, 3), dtype)
        self.k.project_forward(
            _np(means), _np(quats), _np(scales), _np(opacities), sh_in, _np(viewmats), _np(ks),
            width, height, float(near), float(far), sh_degree, dense,
        )  # fmt: skip
        rows = np.flatnonzero(dense[-1])
        m = max(n, 1)
        gathered = [torch.from_numpy(a.reshape(n_cams * n, *a.shape[2:])[rows]) for a in dense[:-1]]
        return [*gathered, torch.from_numpy(rows // m), torch.from_numpy(rows % m)]

    def project_backward(self, means, quats, scales, sh, viewmats, ks, width, height, sh_degree, cam_ids, gauss_ids,
                         g_means2d, g_conics, g_rgb, g_depth, geometry):  # fmt: skip
        self._threads()
        dtype = _np(means).dtype
        outs = [np.zeros(t.shape if geometry else (0,) * t.dim(), dtype) for t in (means, quats, scales, sh)]
        colour = sh_degree >= 0
        if not colour:  # no SH: an empty stand-in of the shapes numba compiled for
            outs[3] = np.zeros((0, 1, 3), dtype)
        elif not geometry:
            outs[3] = np.zeros(sh.shape, dtype)
        sh_in = _np(sh) if colour else outs[3]
        g_rgb_in = _np(g_rgb) if colour else np.zeros((0, 3), dtype)
        grads = (_np(g_means2d), _np(g_conics), g_rgb_in, _np(g_depth))
        self.k.project_backward(
            _np(means), _np(quats), _np(scales), sh_in, _np(viewmats), _np(ks), width, height, sh_degree,
            _np(cam_ids), _np(gauss_ids), grads, geometry, tuple(outs),
        )  # fmt: skip
        if not colour:
            outs[3] = np.zeros(0, dtype)
        return [torch.from_numpy(t) for t in outs]
