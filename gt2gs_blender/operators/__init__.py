"""Blender operators. Each submodule registers its own classes and menu entries.

Operator ids scripts rely on: ``gt2gs.import_ply`` and ``gt2gs.export_ply`` (both take ``filepath``).
"""
from __future__ import annotations

from ..blender.registration import ModuleGroup
from . import io_export, io_import

_group = ModuleGroup((io_import, io_export))
register = _group.register
unregister = _group.unregister
