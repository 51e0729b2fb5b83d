"""Blender UI: the GT² tab in the 3D View sidebar."""
from __future__ import annotations

from . import sidebar

modules = (sidebar,)
_registered: list = []


def register() -> None:
    try:
        for module in modules:
            module.register()
            _registered.append(module)
    except BaseException:
        unregister()
        raise


def unregister() -> None:
    while _registered:
        _registered.pop().unregister()
