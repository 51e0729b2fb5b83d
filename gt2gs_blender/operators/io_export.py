"""File ▸ Export ▸ Gaussian Splat (.ply): the active splat object back to an INRIA PLY file."""

from __future__ import annotations

import os

import bpy
from bpy.props import BoolProperty, EnumProperty, StringProperty
from bpy_extras.io_utils import ExportHelper

from ..blender import splats
from ..blender.registration import ClassesWithMenu
from .io_import import engine_missing_message

FORMATS = {
    "SOURCE": None,
    "BINARY": "binary_little_endian",
    "ASCII": "ascii",
}


def export_target(context):
    """The splat object to export: the active object, else the only selected splat object."""
    active = context.active_object
    if splats.is_splat_object(active):
        return active
    selected = [obj for obj in getattr(context, "selected_objects", ()) if splats.is_splat_object(obj)]
    return selected[0] if len(selected) == 1 else None


class GT2GS_OT_export_ply(bpy.types.Operator, ExportHelper):
    """Export the active Gaussian splat object as a 3D Gaussian Splatting .ply file"""

    bl_idname = "gt2gs.export_ply"
    bl_label = "Export Gaussian Splat"
    bl_options = {"REGISTER"}

    filename_ext = ".ply"
    filter_glob: StringProperty(default="*.ply", options={"HIDDEN"})

    bake_transform: BoolProperty(
        name="Apply Object Transform",
        description="Bake the object's location, rotation and scale into the splats (positions, rotations, "
        "scales and view-dependent colour); off writes them in the object's own space",
        default=False,
    )
    ply_format: EnumProperty(
        name="Format",
        items=(
            ("SOURCE", "As Imported", "The imported file's encoding (binary little-endian for other objects)"),
            ("BINARY", "Binary", "binary_little_endian, what 3DGS tools write"),
            ("ASCII", "ASCII", "Human-readable text, much larger and slower"),
        ),
        default="SOURCE",
    )

    @classmethod
    def poll(cls, context):
        if export_target(context) is None:
            cls.poll_message_set("Select a Gaussian splat point cloud to export")
            return False
        return True

    def invoke(self, context, event):
        if not self.filepath:
            obj = export_target(context)
            folder = os.path.dirname(bpy.data.filepath) if bpy.data.filepath else ""
            self.filepath = os.path.join(folder, bpy.path.clean_name(obj.name) + self.filename_ext)
        return super().invoke(context, event)

    def execute(self, context):
        obj = export_target(context)
        if obj is None:
            self.report({"ERROR"}, "No Gaussian splat object to export (select a point cloud imported as splats)")
            return {"CANCELLED"}
        try:
            from ..core.errors import GT2GSError
            from ..core.scene.ply_write import write_ply
        except ImportError as exc:
            self.report({"ERROR"}, engine_missing_message(exc))
            return {"CANCELLED"}

        fmt = FORMATS[self.ply_format] or splats.get_meta(obj.data).get("format") or "binary_little_endian"
        path = bpy.path.abspath(self.filepath)
        try:
            scene, notes = splats.object_to_scene(obj, bake_transform=self.bake_transform)
            write_ply(path, scene, fmt=fmt)
        except (GT2GSError, splats.SplatObjectError, ValueError) as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        except OSError as exc:
            self.report({"ERROR"}, f"{path}: cannot be written ({exc.strerror or exc})")
            return {"CANCELLED"}
        for note in notes:
            self.report({"WARNING"}, note)
        self.report({"INFO"}, f"Exported {len(scene):,} splats to {path}")
        return {"FINISHED"}


def menu_func_export(self, context):
    self.layout.operator(GT2GS_OT_export_ply.bl_idname, text="Gaussian Splat (.ply)")


_registration = ClassesWithMenu((GT2GS_OT_export_ply,), "TOPBAR_MT_file_export", menu_func_export)
register = _registration.register
unregister = _registration.unregister
