"""GT² Texture Transfer: geometry-aware texture transfer for 3D Gaussian Splatting scenes in Blender.

This file only registers the Blender parts. Blender modules are imported inside register() so the
package (and its bpy-free ``core``) also imports in plain Python for the API, CLI and worker.
"""
from __future__ import annotations

_registered: list = []


def register() -> None:
    """Register the extension's Blender classes (called by Blender when the extension is enabled)."""
    from . import operators, panels

    for module in (operators, panels):
        module.register()
        _registered.append(module)


def unregister() -> None:
    """Unregister everything register() registered, in reverse order."""
    while _registered:
        _registered.pop().unregister()
