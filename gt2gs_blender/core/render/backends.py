"""Which rasterizer backend runs: what is usable on a device, and ``auto``'s pick."""

from __future__ import annotations

import logging
from typing import Any

import torch

from . import cpu_backend, gsplat_backend, numba_backend

BACKENDS = ("torch", "cpu", "numba", "gsplat")
KERNEL_BACKENDS = ("cpu", "numba")
"""The backends that run a compiled kernel with cpu_backend's functions: C++, or its numba port."""
log = logging.getLogger(__name__)


def available_backends(device: torch.device | str = "cpu") -> list[str]:
    """Backends that can render on ``device`` here, fastest first."""
    device = torch.device(device)
    if device.type == "cuda":
        return (["gsplat"] if gsplat_backend.available() else []) + ["torch"]
    usable = [name for name in KERNEL_BACKENDS if kernel(name) is not None]
    return [*usable, "torch"]


def kernel(name: str) -> Any:
    """The compiled kernel of a kernel backend (C++ or numba), None when it cannot run here."""
    return cpu_backend.load_kernel() if name == "cpu" else numba_backend.load_kernel()


def unavailable_reason(name: str) -> str:
    """Why a backend cannot run here, in a few words."""
    if name == "cpu":
        return str(cpu_backend.unavailable_reason())
    if name == "numba":
        return str(numba_backend.unavailable_reason())
    return "needs CUDA and the gsplat package"


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
        on_cpu = backend in KERNEL_BACKENDS and torch.device(device).type == "cpu"
        reason = unavailable_reason(backend) if on_cpu else f"not usable on {torch.device(device)}"
        log.warning("rasterizer backend %r unavailable (%s); using %r", backend, reason, usable[0])
        return usable[0]
    return backend
