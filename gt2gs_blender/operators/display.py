"""Render ▸ Set Up Scene for Splats (``gt2gs.setup_scene``): the settings the Gaussian display needs to match
the rasterizer."""

from __future__ import annotations

import bpy

from ..blender import display
from ..blender.registration import ClassesWithMenu


class GT2GS_OT_setup_scene(bpy.types.Operator):
    """Set the Standard view transform, enough Cycles transparent bounces and EEVEE blending for faithful splats"""

    bl_idname = "gt2gs.setup_scene"
    bl_label = "Set Up Scene for Splats"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        """Apply ``display.setup_scene`` to the current scene."""
        display.setup_scene(context.scene)
        self.report({"INFO"}, "Scene set up for Gaussian splats (Standard view transform, transparent bounces)")
        return {"FINISHED"}


def menu_func_render(self, context):
    self.layout.operator(GT2GS_OT_setup_scene.bl_idname)


_registration = ClassesWithMenu((GT2GS_OT_setup_scene,), "TOPBAR_MT_render", menu_func_render)
register = _registration.register
unregister = _registration.unregister
