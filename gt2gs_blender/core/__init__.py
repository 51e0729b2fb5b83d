"""The bpy-free engine and its library API. Never imports bpy or a front end.

The public API is importable from here, loaded on first use so that ``import gt2gs_blender.core``
stays light (Blender imports numpy-only parts of the engine without torch)::

    from gt2gs_blender.core import read_ply, write_ply, auto_views, load_views, render, preset, transfer

OpenMP threads (torch's and the C++ rasterizer's) sleep instead of spinning while they wait,
unless the caller chose otherwise: with any other busy process on the machine (Blender's UI, a
second job), spinning threads made renders 5-8x slower (measured on 2 cores), while sleeping costs
little when the machine is idle. This only takes effect when set before torch is first imported.
"""

import importlib
import os
from typing import Any

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

API = {
    "GaussianScene": "scene.gaussians",
    "read_ply": "scene.ply",
    "write_ply": "scene.ply_write",
    "Camera": "cameras.camera",
    "auto_views": "cameras.generate",
    "load_views": "cameras.files",
    "render": "render",
    "TransferConfig": "transfer.config",
    "PRESETS": "transfer.config",
    "preset": "transfer.config",
    "transfer": "transfer.pipeline",
    "TransferResult": "transfer.pipeline",
    "Progress": "progress",
    "Cancelled": "progress",
    "GT2GSError": "errors",
}
"""Public name -> the module (under ``core``) that defines it."""

__all__ = sorted(API)


def __getattr__(name: str) -> Any:
    """Load a public name's module on first access (PEP 562)."""
    if name not in API:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(f"{__name__}.{API[name]}"), name)
