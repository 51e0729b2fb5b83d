"""Blender UI: the scene's GT² settings, the GT² tab in the 3D View sidebar, the preferences."""

from __future__ import annotations

from ..blender.registration import ModuleGroup
from . import parts, preferences, result, sections, settings, sidebar, transfer_panel

_group = ModuleGroup((settings, sidebar, transfer_panel, parts, sections, result, preferences))
register = _group.register
unregister = _group.unregister
