"""Blender operators. Each submodule registers its own classes and menu entries.

Operator ids scripts rely on: ``gt2gs.import_ply`` and ``gt2gs.export_ply`` (both take ``filepath``),
``gt2gs.transfer_texture`` and ``gt2gs.preview_orientation`` (``texture_path``, ``preset``, ``angle``,
``n_views`` override the panel's settings), ``gt2gs.setup_scene`` (render settings for the splat display),
``gt2gs.find_parts``, ``gt2gs.select_part`` (``part``: its splats become the selection Selected Points Only
restyles) and ``gt2gs.select_whole_parts`` (the selected splats grown to their parts).
"""

from __future__ import annotations

from ..blender.registration import ModuleGroup
from . import dependencies, display, io_export, io_import, machine, parts, transfer

_group = ModuleGroup((io_import, io_export, display, transfer, parts, dependencies, machine))
register = _group.register
unregister = _group.unregister
