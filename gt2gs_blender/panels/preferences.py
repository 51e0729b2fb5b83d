"""The extension's preferences: dependency status and install, and the machine settings (device, threads,
weights, rasterizer, caches) generated from the transfer settings' metadata."""

from __future__ import annotations

import bpy
from bpy.props import EnumProperty

from ..app import deps
from ..blender import addon, properties
from ..core.transfer.config import IN_PREFERENCES, user_settings
from ..operators import dependencies


def dependency_rows(deps_dir: str | None) -> list[tuple[str, str, bool]]:
    """(package, what is installed, ok) per required package, as the worker will see them."""
    rows = []
    for dep in deps.dependency_status(deps_dir):
        found = f"{dep.version}" if dep.ok else "missing"
        if dep.ok and not dep.matches_pin:
            found += f" (tested: {dep.pinned})"
        rows.append((dep.module, found, dep.ok))
    return rows


class GT2GS_AP_preferences(bpy.types.AddonPreferences):
    """Dependencies, and the machine settings every transfer of this Blender uses (device, threads, weights)."""

    bl_idname = addon.ADDON_ID
    __annotations__ = {
        "build": EnumProperty(
            name="Torch Build",
            default="CPU",
            items=(
                ("CPU", "CPU", "The CPU-only torch (smaller download, any machine)"),
                ("CUDA", "CUDA", "torch for NVIDIA GPUs (CUDA 12.8, a large download)"),
            ),
        ),
        **properties.annotations(IN_PREFERENCES),
    }

    def draw(self, context):
        layout = self.layout
        box = layout.box()
        box.label(text="Python Dependencies (used by the transfer worker)")
        folder = addon.deps_dir()
        column = box.column(align=True)
        for module, found, ok in dependency_rows(folder):
            row = column.split(factor=0.3)
            row.label(text=module, icon="CHECKMARK" if ok else "ERROR")
            row.label(text=found)
        box.label(text=f"Install folder: {folder or 'not an installed extension'}")
        row = box.row()
        row.prop(self, "build", expand=True)
        row.operator(dependencies.GT2GS_OT_install_dependencies.bl_idname, icon="IMPORT")
        if not bpy.app.online_access:
            box.label(text="Allow Online Access (Preferences ▸ System) to download packages", icon="INFO")
        column = layout.column()
        column.use_property_split = True
        for name, _, _ in user_settings(IN_PREFERENCES):
            column.prop(self, name)


classes = (GT2GS_AP_preferences,)

register, unregister = bpy.utils.register_classes_factory(classes)
