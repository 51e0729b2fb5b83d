"""Blender UI: the GT² tab in the 3D View sidebar."""
from __future__ import annotations

from ..blender.registration import ModuleGroup
from . import sidebar

_group = ModuleGroup((sidebar,))
register = _group.register
unregister = _group.unregister
