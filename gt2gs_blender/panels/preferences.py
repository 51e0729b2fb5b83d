"""The extension's preferences: dependency status and install, weights folder, default device, CPU threads."""
from __future__ import annotations

import bpy
from bpy.props import EnumProperty, IntProperty, StringProperty

from ..blender import addon
from ..app import deps
from ..operators import dependencies


def dependency_rows(deps_dir: str | None) -> list[tuple[str, str, bool]]:
    """(package, what is installed, ok) per required package, as the worker will see them."""
    rows = []
    for dep in deps.dependency_status(deps_dir):
        found = f"{dep.version}" if dep.ok else "missing"
        if dep.ok and dep.version != dep.pinned:
            found += f" (tested: {dep.pinned})"
        rows.append((dep.module, found, dep.ok))
    return rows


class GT2GS_AP_preferences(bpy.types.AddonPreferences):
    bl_idname = addon.ADDON_ID

    build: EnumProperty(
        name="Torch Build", default="CPU",
        items=(("CPU", "CPU", "The CPU-only torch (smaller download, any machine)"),
               ("CUDA", "CUDA", "torch for NVIDIA GPUs (CUDA 12.8, a large download)")))
    weights_dir: StringProperty(
        name="Weights Folder", subtype="DIR_PATH",
        description="Folder with VGG weights (vgg16-397923af.pth or vgg19_normalised_to_relu3_1.pth); "
                    "empty: $GT2GS_WEIGHTS_DIR, then torch's cache")
    device: EnumProperty(
        name="Default Device", default="AUTO",
        items=(("AUTO", "Auto", "CUDA when available, else CPU"), ("CPU", "CPU", ""), ("CUDA", "CUDA", "")))
    threads: IntProperty(
        name="CPU Threads", default=0, min=0, soft_max=64,
        description="Threads the transfer worker uses on the CPU; 0: one per physical core. "
                    "Fewer keeps Blender more responsive while a transfer runs")

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
        layout.prop(self, "weights_dir")
        layout.prop(self, "device")
        layout.prop(self, "threads")


classes = (GT2GS_AP_preferences,)

register, unregister = bpy.utils.register_classes_factory(classes)
