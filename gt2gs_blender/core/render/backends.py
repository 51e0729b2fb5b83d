"""Which rasterizer backend runs: what is usable on a device, and ``auto``'s pick."""

from __future__ import annotations

import logging

import torch

from . import cpu_backend, gsplat_backend

BACKENDS = ("torch", "cpu", "gsplat")
log = logging.getLogger(__name__)


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
