"""File ▸ Export ▸ Gaussian Splat: the active splat object as an INRIA PLY, compressed PLY, SPZ or .splat file."""

from __future__ import annotations

import os

import bpy
from bpy.props import BoolProperty, EnumProperty, StringProperty
from bpy_extras.io_utils import ExportHelper

from ..blender import splats
from ..blender.registration import ClassesWithMenu
from ..core.scene.files import FORMATS, PLY, WRITE_EXTENSIONS, WRITERS
from .io_import import engine_missing_message

ENCODINGS = {
    "SOURCE": None,
    "BINARY": "binary_little_endian",
    "ASCII": "ascii",
}
FILE_FORMATS = (
    ("AUTO", "From File Name", "The format the file name ends with (.ply when it names none)"),
    *((fmt, FORMATS[fmt].label, f"{FORMATS[fmt].extensions[0]}: keeps {FORMATS[fmt].keeps}") for fmt in WRITERS),
)

MENU_ENDINGS = tuple(ext for ext in WRITE_EXTENSIONS if ext.count(".") == 1)
"""The endings the File menu names (``.compressed.ply`` is a ``.ply``)."""
EXPORT_GLOB = ";".join(f"*{FORMATS[fmt].extensions[0]}" for fmt in WRITERS)
"""What the file browser shows (Blender evaluates property annotations apart from the module's names)."""


def export_target(context):
    """The splat object to export: the active object, else the only selected splat object."""
    active = context.active_object
    if splats.is_splat_object(active):
        return active
    selected = [obj for obj in getattr(context, "selected_objects", ()) if splats.is_splat_object(obj)]
    return selected[0] if len(selected) == 1 else None


def imported_from(path: str, obj, overwrites) -> object | None:
    """The splat object (``obj`` first, then any in the file) whose imported original writing ``path`` would
    replace (a transfer's result keeps its original's), else None."""
    for candidate in (obj, *bpy.data.objects):
        source = splats.get_meta(candidate.data).get("source") if splats.is_splat_object(candidate) else None
        if source and overwrites(path, source):
            return candidate
    return None


class GT2GS_OT_export_ply(bpy.types.Operator, ExportHelper):
    """Export the active Gaussian splat object as a splat file (PLY, compressed PLY, SPZ or .splat)"""

    bl_idname = "gt2gs.export_ply"
    bl_label = "Export Gaussian Splat"
    bl_options = {"REGISTER"}

    filename_ext = ".ply"
    check_extension = None  # the name's ending chooses the format unless File Format names one (see check)
    filter_glob: StringProperty(default=EXPORT_GLOB, options={"HIDDEN"})
    file_format: EnumProperty(name="File Format", items=FILE_FORMATS, default="AUTO")

    bake_transform: BoolProperty(
        name="Apply Object Transform",
        description="Bake the object's location, rotation and scale into the splats (positions, rotations, "
        "scales and view-dependent colour); off writes them in the object's own space",
        default=False,
    )
    overwrite_source: BoolProperty(
        name="Overwrite Imported File",
        description="Allow writing over the file this object was imported from (a transfer's result: its "
        "original's); otherwise that is refused, so the original is never replaced by accident",
        default=False,
    )
    ply_format: EnumProperty(
        name="PLY Encoding",
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

    def check(self, context) -> bool:
        """With a File Format chosen, give the file name that format's ending; True when it changed."""
        if self.file_format == "AUTO":
            return False
        path = splat_stem(self.filepath) + FORMATS[self.file_format].extensions[0]
        changed, self.filepath = path != self.filepath, path
        return changed

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
            from ..core.atomic import check_outputs, overwrites
            from ..core.errors import GT2GSError
            from ..core.scene.files import output_format, write_splats
            from ..core.scene.ply_write import write_ply
        except ImportError as exc:
            self.report({"ERROR"}, engine_missing_message(exc))
            return {"CANCELLED"}

        encoding = ENCODINGS[self.ply_format] or splats.get_meta(obj.data).get("format") or "binary_little_endian"
        path = bpy.path.abspath(self.filepath)
        owner = None if self.overwrite_source else imported_from(path, obj, overwrites)
        if owner is not None:
            self.report(
                {"ERROR"},
                f"{path}: is your imported original, the file {owner.name!r} comes from; choose another path, or "
                "tick Overwrite Imported File to replace it",
            )
            return {"CANCELLED"}
        try:
            check_outputs([("the export", path)], [])
            fmt = output_format(path, None if self.file_format == "AUTO" else self.file_format)
            scene, notes = splats.object_to_scene(obj, bake_transform=self.bake_transform)
            if fmt == PLY:
                write_ply(path, scene, fmt=encoding)
            else:
                notes += write_splats(path, scene, fmt)
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


def splat_stem(path: str) -> str:
    """A file path without its splat-format ending (``.compressed.ply`` whole)."""
    endings = sorted(WRITE_EXTENSIONS, key=len, reverse=True)
    return next((path[: -len(ext)] for ext in endings if path.lower().endswith(ext)), path)


def menu_func_export(self, context):
    self.layout.operator(GT2GS_OT_export_ply.bl_idname, text=f"Gaussian Splat ({', '.join(MENU_ENDINGS)})")


_registration = ClassesWithMenu((GT2GS_OT_export_ply,), "TOPBAR_MT_file_export", menu_func_export)
register = _registration.register
unregister = _registration.unregister
