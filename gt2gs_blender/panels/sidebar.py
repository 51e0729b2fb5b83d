"""The GT² tab in the 3D View sidebar (N panel): the active splat object, Import and Export.

What the panel shows comes from ``splat_rows`` (tested without a UI); ``draw`` only lays it out.
"""

from __future__ import annotations

import os
import textwrap

import bpy

from ..blender import splats, transfer_run

CATEGORY = "GT²"
LABEL_CHARS = 14
"""The longest label that fits a property's label column at Blender's default sidebar width and UI scale (a
5.2 window cut "Split Splats Ab…" and "Texture Rotati…" at 15); a longer one gets a row of its own."""
VALUE_CHARS = 20
"""The longest value that fits beside its label (the label takes 40 % of the row)."""
LINE_CHARS = 34
"""The longest text that fits across the default sidebar (Blender does not wrap labels)."""


def text_lines(layout, text: str, icon: str = "NONE") -> None:
    """``text`` as labels of at most ``LINE_CHARS`` characters across the panel, the icon on the first."""
    for i, line in enumerate(textwrap.wrap(text, LINE_CHARS) or [""]):
        layout.label(text=line, icon=icon if i == 0 else "BLANK1")


def value_rows(layout, rows: list[tuple[str, str]]) -> None:
    """(label, value) rows: side by side when the value fits, else the value on its own lines under the label."""
    column = layout.column(align=True)
    for label, value in rows:
        if len(value) <= VALUE_CHARS and len(label) <= LABEL_CHARS:
            split = column.split(factor=0.4)
            split.label(text=label)
            split.label(text=value)
        else:
            column.label(text=label)
            text_lines(column, value, icon="BLANK1")


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
    """What the selected splat object holds (its splats, SH degree, extra properties, file); import and export"""

    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = CATEGORY
    bl_label = "Gaussian Splat"

    def draw(self, context):
        layout = self.layout
        rows = splat_rows(context.active_object)
        if rows is None:
            layout.label(text=transfer_run.NO_TARGET, icon="INFO")
        else:
            value_rows(layout, rows)
        row = layout.row(align=True)
        row.operator("gt2gs.import_ply", text="Import", icon="IMPORT")
        row.operator("gt2gs.export_ply", text="Export", icon="EXPORT")
        layout.operator("gt2gs.setup_scene", icon="SCENE")


classes = (VIEW3D_PT_gt2gs_splat,)

register, unregister = bpy.utils.register_classes_factory(classes)
