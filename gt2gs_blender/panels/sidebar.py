"""The GT² tab in the 3D View sidebar (N panel): the active splat object, Import and Export.

What the panel shows comes from ``splat_rows`` (tested without a UI); ``draw`` only lays it out.
"""

from __future__ import annotations

import os

import bpy

from ..blender import splats

CATEGORY = "GT²"
NO_SPLAT_TEXT = "Select a Gaussian splat object"


def splat_rows(obj) -> list[tuple[str, str]] | None:
    """(label, value) rows describing ``obj``, or None when it is not a splat object."""
    summary = splats.splat_summary(obj)
    if summary is None:
        return None
    extras = ", ".join(summary.extras) if len(summary.extras) <= 3 else f"{len(summary.extras)} properties"
    rows = [
        ("Object", summary.name),
        ("Splats", f"{summary.count:,}"),
        ("SH Degree", str(summary.sh_degree) if summary.sh_degree >= 0 else "incomplete f_rest"),
        ("Extras", extras or "none"),
    ]
    if summary.source:
        rows.append(("Source", os.path.basename(summary.source)))
    return rows


class VIEW3D_PT_gt2gs_splat(bpy.types.Panel):
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = CATEGORY
    bl_label = "Gaussian Splat"

    def draw(self, context):
        layout = self.layout
        rows = splat_rows(context.active_object)
        if rows is None:
            layout.label(text=NO_SPLAT_TEXT, icon="INFO")
        else:
            column = layout.column(align=True)
            for label, value in rows:
                split = column.split(factor=0.4)
                split.label(text=label)
                split.label(text=value)
        row = layout.row(align=True)
        row.operator("gt2gs.import_ply", text="Import", icon="IMPORT")
        row.operator("gt2gs.export_ply", text="Export", icon="EXPORT")
        layout.operator("gt2gs.setup_scene", icon="SCENE")


classes = (VIEW3D_PT_gt2gs_splat,)

register, unregister = bpy.utils.register_classes_factory(classes)
