"""File ▸ Import ▸ Gaussian Splat, and drag-and-drop of splat files (PLY, compressed PLY, SOG, SPZ, .splat) into
the 3D viewport."""

from __future__ import annotations

import os
import warnings

import bpy
from bpy.props import BoolProperty, CollectionProperty, StringProperty
from bpy_extras.io_utils import ImportHelper

from ..blender import display, splats
from ..blender.registration import ClassesWithMenu
from ..core.scene.files import READ_EXTENSIONS, SOG_META

IMPORT_GLOB = ";".join(f"*{ext}" for ext in READ_EXTENSIONS) + f";{SOG_META}"
"""What the file browser offers (compressed PLYs are .ply files; an unpacked SOG folder is imported through
its meta.json)."""


def engine_missing_message(exc: ImportError) -> str:
    """One line for a user whose Blender lacks the engine's Python packages (torch is not bundled)."""
    return (
        f"GT² needs its Python dependencies to read and write splat files ({exc.name or exc} is not "
        "installed in Blender's Python)"
    )


class GT2GS_OT_import_ply(bpy.types.Operator, ImportHelper):
    """Import Gaussian splat files (PLY, compressed PLY, SOG, SPZ, .splat) as point-cloud objects"""

    bl_idname = "gt2gs.import_ply"
    bl_label = "Import Gaussian Splat"
    bl_options = {"REGISTER", "UNDO"}

    filename_ext = ".ply"
    filter_glob: StringProperty(default=IMPORT_GLOB, options={"HIDDEN"})
    directory: StringProperty(subtype="DIR_PATH", options={"HIDDEN", "SKIP_SAVE"})
    files: CollectionProperty(type=bpy.types.OperatorFileListElement, options={"HIDDEN", "SKIP_SAVE"})

    drop_invalid: BoolProperty(
        name="Drop Invalid Splats",
        description="Load files with NaN/Inf parameters by leaving those splats out (otherwise such a file is refused)",
        default=False,
    )
    add_material: BoolProperty(
        name="Splat Material",
        description="Give the object a material that shows the splat colours in Material Preview and renders",
        default=True,
    )

    setup_scene: BoolProperty(
        name="Set Up Scene",
        description="Set the Standard view transform and the Cycles/EEVEE settings the splat display needs",
        default=False,
    )

    def invoke(self, context, event):
        return self.invoke_popup(context)  # a confirmation for drag-and-drop, else the file browser

    def execute(self, context):
        paths = self._paths()
        if not paths:
            self.report({"ERROR"}, "No file to import")
            return {"CANCELLED"}
        try:
            from ..core.errors import GT2GSError, NotGaussianPlyError
        except ImportError as exc:
            self.report({"ERROR"}, engine_missing_message(exc))
            return {"CANCELLED"}

        if context.mode != "OBJECT" and context.active_object is not None:
            bpy.ops.object.mode_set(mode="OBJECT")
        collection = _target_collection(context)
        material_before = splats.find_material()
        created: list[bpy.types.Object] = []
        notes: list[str] = []

        def undo_partial_import() -> None:
            _remove_objects(created)
            material = splats.find_material()
            if material_before is None and material is not None and not material.users:
                bpy.data.materials.remove(material)
            display.remove_unused()

        try:
            for path in paths:
                with warnings.catch_warnings(record=True) as caught:
                    warnings.simplefilter("always")
                    scene, encoding = read_any(path, self.drop_invalid)
                notes.extend(str(w.message) for w in caught)
                created.append(
                    splats.scene_to_object(
                        scene,
                        object_name_for(path),
                        collection,
                        source_path=path,
                        source_format=encoding,
                        with_material=self.add_material,
                    )
                )
        except NotGaussianPlyError as exc:
            undo_partial_import()
            self.report({"ERROR"}, f"{exc}; import it with File ▸ Import ▸ Stanford PLY (.ply)")
            return {"CANCELLED"}
        except (GT2GSError, splats.SplatObjectError) as exc:
            undo_partial_import()
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        except MemoryError:
            failed = paths[len(created)]
            undo_partial_import()
            self.report({"ERROR"}, f"{failed}: not enough memory to import it")
            return {"CANCELLED"}
        except BaseException:  # a bug: leave the scene as it was, let Blender show the traceback
            undo_partial_import()
            raise

        if self.setup_scene:
            display.setup_scene(context.scene)
        for obj in context.view_layer.objects.selected:
            obj.select_set(False)
        for obj in created:
            if obj.visible_get():
                obj.select_set(True)
        context.view_layer.objects.active = created[-1]
        for note in notes:
            self.report({"WARNING"}, note)
        total = sum(len(obj.data.points) for obj in created)
        self.report({"INFO"}, f"Imported {total:,} splats from {len(created)} file{'s' * (len(created) > 1)}")
        return {"FINISHED"}

    def _paths(self) -> list[str]:
        if self.directory and any(f.name for f in self.files):
            paths = [os.path.join(self.directory, f.name) for f in self.files if f.name]
        else:
            paths = [self.filepath] if self.filepath else []
        return [os.path.abspath(bpy.path.abspath(p)) for p in paths]  # "//" = beside the .blend file


class GT2GS_FH_ply(bpy.types.FileHandler):
    """Drop splat files on the 3D viewport to import them as Gaussian splats."""

    bl_idname = "GT2GS_FH_ply"
    bl_label = "Gaussian Splat"
    bl_import_operator = GT2GS_OT_import_ply.bl_idname
    bl_file_extensions = ";".join(READ_EXTENSIONS)

    @classmethod
    def poll_drop(cls, context):
        return context.area is not None and context.area.type == "VIEW_3D"


def read_any(path: str, drop_invalid: bool):
    """A splat file's arrays, and its PLY encoding (None for the other formats); SOG images are decoded by
    Blender, so import needs numpy only."""
    from ..blender.webp import decode_webp
    from ..core.atomic import require_input
    from ..core.scene.files import PLY, SOG, detect_format, read_splats
    from ..core.scene.ply_header import read_ply_header

    require_input("splat file", path, folder=True)  # a named pipe would block Blender
    fmt = detect_format(path)
    options = {"decode_webp": decode_webp} if fmt == SOG else {}
    encoding = read_ply_header(path).format if fmt == PLY else None
    return read_splats(path, drop_invalid=drop_invalid, **options), encoding


def object_name_for(path: str) -> str:
    """The file's name, or for a generic ``point_cloud.ply`` (the trainers') or ``meta.json`` (an unpacked
    SOG) the scene folder's name.

    ``.../garden/point_cloud/iteration_30000/point_cloud.ply`` -> ``garden``.
    """
    stem = bpy.path.display_name_from_filepath(path).removesuffix(".compressed")
    if stem.lower() not in ("point_cloud", "meta"):
        return stem or "Gaussian Splat"
    parts = os.path.normpath(os.path.abspath(path)).split(os.sep)[:-1]
    for part in reversed(parts):
        if part and part.lower() != "point_cloud" and not part.lower().startswith("iteration_"):
            return part
    return stem


def _target_collection(context) -> bpy.types.Collection:
    """The active collection (where Blender's importers put objects) unless it is linked from a library."""
    layer_collection = context.view_layer.active_layer_collection
    if layer_collection is not None and layer_collection.collection.library is None:
        return layer_collection.collection
    return context.scene.collection


def _remove_objects(objects: list) -> None:
    """Remove imported objects with their point clouds (the shared material stays if it was there)."""
    for obj in objects:
        data = obj.data
        bpy.data.objects.remove(obj)
        if data is not None and data.users == 0:
            bpy.data.pointclouds.remove(data)


def menu_func_import(self, context):
    self.layout.operator(GT2GS_OT_import_ply.bl_idname, text=f"Gaussian Splat ({', '.join(READ_EXTENSIONS)})")


_registration = ClassesWithMenu((GT2GS_OT_import_ply, GT2GS_FH_ply), "TOPBAR_MT_file_import", menu_func_import)
register = _registration.register
unregister = _registration.unregister
