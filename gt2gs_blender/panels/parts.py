"""The Parts sub-panel: Find Parts, the parts as a list (colour swatch, "Part N", splats), Select Part, which
selects the picked part's splats, and Select Whole Parts, which grows the splats clicked in Edit Mode to their parts;
both turn on Selected Points Only, so a run and the orientation preview restyle just that
part. The list lives in ``scene.gt2gs_parts`` with the object and point count it was found for; the sub-panel
says when those no longer match (``blender/parts.py``'s ``stale_text``)."""

from __future__ import annotations

import bpy
from bpy.props import CollectionProperty, FloatVectorProperty, IntProperty, PointerProperty

from ..blender import parts, transfer_run
from .sections import draw_setting
from .sidebar import CATEGORY, text_lines

NO_PARTS_TEXT = "Find Parts splits the object by colour and position, to restyle one part"


class GT2GS_PG_part(bpy.types.PropertyGroup):
    """One part of a splat object: its number, splats and mean colour."""

    part: IntProperty(name="Part", description="The part's number (as the command line's parts lists it)")
    splats: IntProperty(name="Splats", description="How many splats the part holds")
    colour: FloatVectorProperty(
        name="Colour", subtype="COLOR", size=3, min=0.0, max=1.0, description="The part's average colour"
    )


class GT2GS_PG_parts(bpy.types.PropertyGroup):
    """The parts found for an object, and which object and point count they were found for."""

    items: CollectionProperty(type=GT2GS_PG_part)
    active: IntProperty(name="Part", description="The part Select Part selects")
    object: PointerProperty(type=bpy.types.Object, name="Object", description="The object the parts were found for")
    point_count: IntProperty(name="Points", description="The object's points when its parts were found")


class GT2GS_UL_parts(bpy.types.UIList):
    """A part per row: its colour, its number and how many splats it holds."""

    def draw_item(self, context, layout, data, item, icon, active_data, active_property, index=0, flt_flag=0):
        row = layout.row(align=False)
        swatch = row.row()
        swatch.ui_units_x = 1.5
        swatch.prop(item, "colour", text="")
        row.label(text=f"Part {item.part}")
        row.label(text=f"{item.splats:,} splats")


class VIEW3D_PT_gt2gs_parts(bpy.types.Panel):
    """Split the splat object into parts by colour and position, and pick one to restyle alone"""

    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = CATEGORY
    bl_label = "Parts"
    bl_parent_id = "VIEW3D_PT_gt2gs_transfer"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        store = context.scene.gt2gs_parts
        layout.operator("gt2gs.find_parts", icon="STICKY_UVS_DISABLE")
        if not store.items:
            text_lines(layout, NO_PARTS_TEXT, icon="INFO")
            return
        stale = parts.stale_text(store, transfer_run.target_object(context))
        if stale:
            text_lines(layout.box(), stale, icon="ERROR")
        column = layout.column()
        column.enabled = stale is None
        column.template_list("GT2GS_UL_parts", "", store, "items", store, "active", rows=3)
        buttons = column.column(align=True)
        buttons.operator("gt2gs.select_part", icon="RESTRICT_SELECT_OFF")
        buttons.operator("gt2gs.select_whole_parts", icon="SELECT_EXTEND")
        draw_setting(layout, context.scene.gt2gs, "region_only", None)


classes = (GT2GS_PG_part, GT2GS_PG_parts, GT2GS_UL_parts, VIEW3D_PT_gt2gs_parts)


def register() -> None:
    for cls in classes:
        bpy.utils.register_class(cls)
    bpy.types.Scene.gt2gs_parts = PointerProperty(type=GT2GS_PG_parts)


def unregister() -> None:
    del bpy.types.Scene.gt2gs_parts
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
