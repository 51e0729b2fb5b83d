"""Find Parts, Select Part and Select Whole Parts (``gt2gs.find_parts``, ``gt2gs.select_part``,
``gt2gs.select_whole_parts``): split the splat object into parts by colour and position, then select a part's splats
(picked in the list, or grown from splats clicked in Edit Mode) so Selected Points Only restyles just that part (the
guitar's body and not its stand)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import bpy
from bpy.props import BoolProperty, IntProperty

from ..blender import parts, splats, transfer_run


def _parts_found(cls, context) -> bool:
    """Poll of the selecting operators: a target whose parts were found (stale ones are refused when run)."""
    if transfer_run.polled_target(cls, context) is None:
        return False
    if not context.scene.gt2gs_parts.items:
        cls.poll_message_set("Find Parts first")
        return False
    return True


class GT2GS_OT_find_parts(bpy.types.Operator):
    """Split the splat object into parts by colour and position (a guitar's body, neck and stand), to restyle one"""

    bl_idname = "gt2gs.find_parts"
    bl_label = "Find Parts"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return transfer_run.polled_target(cls, context) is not None

    def execute(self, context):
        obj = transfer_run.target_object(context)
        context.window_manager.progress_begin(0, 1)
        try:
            count = parts.find(obj, context.scene.gt2gs_parts)
        except splats.SplatObjectError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        finally:
            context.window_manager.progress_end()
        self.report({"INFO"}, f"{obj.name!r} has {count} part{'s' if count != 1 else ''}")
        return {"FINISHED"}


class GT2GS_OT_select_part(bpy.types.Operator):
    """Select this part's splats in Edit Mode (Shift: add them) and restyle only them (turns on Selected Points Only)"""

    bl_idname = "gt2gs.select_part"
    bl_label = "Select Part"
    bl_options = {"REGISTER", "UNDO"}

    part: IntProperty(
        name="Part", default=-1, min=-1, description="The part to select (-1: the one picked in the list)"
    )

    extend: BoolProperty(
        name="Extend", default=False, description="Add the part to the selection (Shift-click) instead of replacing it"
    )

    poll = classmethod(_parts_found)

    def invoke(self, context, event):
        if not self.properties.is_property_set("extend"):
            self.extend = event.shift
        return self.execute(context)

    def execute(self, context):
        store = context.scene.gt2gs_parts
        part = self.part if self.part >= 0 else store.active
        return _select(self, context, lambda obj: parts.select(obj, store, part, self.extend), part)


class GT2GS_OT_select_whole_parts(bpy.types.Operator):
    """Grow the splats selected in Edit Mode to their whole parts: click a splat of the body, then this"""

    bl_idname = "gt2gs.select_whole_parts"
    bl_label = "Select Whole Parts"
    bl_options = {"REGISTER", "UNDO"}

    poll = classmethod(_parts_found)

    def execute(self, context):
        store = context.scene.gt2gs_parts
        return _select(self, context, lambda obj: parts.grow(obj, store), None)


def _select(op, context, selects: Callable[[Any], list[int]], picked: int | None) -> set[str]:
    """Run ``selects`` on the target (it returns the parts now selected whole), show the selection in Edit Mode
    and restyle only it; the list's pick moves to ``picked`` (None: the first part selected); reports what was
    selected."""
    obj = transfer_run.target_object(context)
    store = context.scene.gt2gs_parts
    try:
        chosen = selects(obj)
    except transfer_run.RunError as exc:
        op.report({"ERROR"}, str(exc))
        return {"CANCELLED"}
    store.active = picked if picked is not None else chosen[0]
    if context.view_layer.objects.active is obj and obj.mode != "EDIT":
        bpy.ops.object.mode_set(mode="EDIT")  # the artist sees the part selected
    context.scene.gt2gs.region_only = True  # a run and the live preview restyle only the selection
    count = int(transfer_run.selection_mask(obj).sum())
    names = ", ".join(str(p) for p in chosen)
    op.report(
        {"INFO"}, f"Part{'s' if len(chosen) > 1 else ''} {names} selected ({count:,} splats); only they are restyled"
    )
    return {"FINISHED"}


classes = (GT2GS_OT_find_parts, GT2GS_OT_select_part, GT2GS_OT_select_whole_parts)

register, unregister = bpy.utils.register_classes_factory(classes)
