"""GT² Texture Transfer: geometry-aware texture transfer for 3D Gaussian Splatting scenes in Blender.

This file only registers the Blender parts. Blender modules are imported inside register() so the
package (and its bpy-free ``core``) also imports in plain Python for the API, CLI and worker.
"""

from __future__ import annotations

_group = None


def register() -> None:
    """Register the extension's Blender classes (called by Blender when the extension is enabled)."""
    global _group
    from . import operators, panels
    from .blender.registration import ModuleGroup

    _group = ModuleGroup((operators, panels))
    _group.register()


def unregister() -> None:
    """Unregister everything register() registered, in reverse order."""
    if _group is not None:
        _group.unregister()
