"""Blender operators. Each submodule registers its own classes and menu entries.

Operator ids scripts rely on: ``gt2gs.import_ply`` and ``gt2gs.export_ply`` (both take ``filepath``).
"""
from __future__ import annotations

from . import io_export, io_import

modules = (io_import, io_export)
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
