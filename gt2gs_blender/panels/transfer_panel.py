"""The GT² tab's Texture Transfer panel: target, preset, Transfer, Cancel, progress and warnings.

Its sub-panels (``sections.py``: Texture, Views, Quality, Advanced; ``parts.py``: Parts; ``result.py``: Result)
hold the rest. What it shows in each state (idle, no weights, running, done, error, no CUDA) comes from
``transfer_view``, a plain function the tests check; ``draw`` only lays that out.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import bpy

from ..blender import machine, transfer_run
from ..blender.job import CANCELLED, DONE, ERROR, IDLE, RUNNING, JobStatus
from ..blender.transfer_run import progress_text
from .sections import draw_setting
from .sidebar import CATEGORY, text_lines

FALLBACK_WARNING = (
    "no VGG weights were found, so a random network stood in and the result is not the method's: set Weights in "
    "the add-on preferences"
)
NO_WEIGHTS_WARNING = (
    "No VGG weights found: a transfer would use a random network and look wrong. Set Weights or download them "
    "in the add-on preferences"
)
ICONS = {IDLE: "INFO", RUNNING: "TIME", DONE: "CHECKMARK", ERROR: "ERROR", CANCELLED: "CANCEL"}


@dataclass(frozen=True)
class TransferView:
    """Everything the main panel shows besides the settings: state, buttons, progress bar, message, warnings."""

    state: str
    can_transfer: bool
    can_cancel: bool
    message: str
    icon: str
    progress: float | None = None
    progress_text: str = ""
    warnings: list[str] = field(default_factory=list)


def transfer_view(
    target: str | None,
    running: JobStatus | None,
    last: transfer_run.Outcome | None,
    *,
    blocker: str | None = None,
    warnings: Sequence[str] = (),
) -> TransferView:
    """What the panel shows for a target object name (None: no splat selected), the running job's status
    (None: none runs), the outcome of the last run, why a transfer cannot run now (``blocker``: no texture
    chosen, a GPU-only preset without CUDA) and warnings about the machine (e.g. no weights)."""
    shown = [*warnings, *([blocker[:1].upper() + blocker[1:]] if blocker else [])]
    if running is not None:
        text = progress_text(running)
        return TransferView(
            RUNNING, False, True, running.message or text, ICONS[RUNNING], running.fraction, text, shown
        )
    can = target is not None and blocker is None
    if last is None:
        message = transfer_run.NO_TARGET if target is None else f"{'Ready' if can else 'Not ready'}: {target}"
        return TransferView(IDLE, can, False, message, ICONS[IDLE], warnings=shown)
    message = {
        DONE: last.message[:1].upper() + last.message[1:],
        CANCELLED: "Cancelled; the scene is unchanged",
        ERROR: f"Failed: {last.message}",
    }.get(last.state, last.message)
    if last.state == DONE and used_fallback(last.report):
        message += f"; {FALLBACK_WARNING}"
        return TransferView(last.state, can, False, message, "ERROR", warnings=shown)
    return TransferView(last.state, can, False, message, ICONS.get(last.state, "INFO"), warnings=shown)


def machine_warnings(state: machine.MachineState) -> list[str]:
    """Warnings the panel shows about this machine before any run: no weights (the random fallback)."""
    weights = (state.info or {}).get("weights") or {}
    return [NO_WEIGHTS_WARNING] if weights.get("fallback") else []


def used_fallback(report: dict[str, Any] | None) -> bool:
    """Whether a run's report says it used the random fallback network (no VGG weights were found)."""
    return bool(((report or {}).get("weights") or {}).get("fallback"))


def current_view(context) -> TransferView:
    """``transfer_view`` for the current context."""
    target = transfer_run.target_object(context)
    run = transfer_run.ACTIVE.get("transfer")
    state = machine.current()
    device = transfer_run.machine_settings(context).get("device", "auto")
    return transfer_view(
        target.name if target else None,
        run.job.status if run else None,
        transfer_run.OUTCOMES.get("transfer"),
        blocker=transfer_run.texture_missing(context.scene.gt2gs)
        or machine.gpu_problem(context.scene.gt2gs.preset, device, state),
        warnings=machine_warnings(state),
    )


class VIEW3D_PT_gt2gs_transfer(bpy.types.Panel):
    """Re-texture the selected splat object with a texture photo (GT²-GS)"""

    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = CATEGORY
    bl_label = "Texture Transfer"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        settings = context.scene.gt2gs
        view = current_view(context)
        layout.prop(settings, "target")
        hint = transfer_run.result_target_hint(context)
        if hint:
            text_lines(layout, hint, icon="INFO")
        layout.prop(settings, "preset")
        row = layout.row()
        row.use_property_split = False  # the two choices across the panel: "New Object" was cut in the split
        row.prop(settings, "result_mode", expand=True)
        draw_setting(layout, settings, "region_only", None)
        for warning in view.warnings:
            text_lines(layout.box(), warning, icon="ERROR")
        row = layout.row(align=True)
        row.scale_y = 1.4
        row.enabled = view.can_transfer
        row.operator("gt2gs.transfer_texture", icon="TEXTURE")
        if view.can_cancel:
            layout.operator("gt2gs.cancel_transfer", icon="CANCEL")
        if view.progress is not None:
            layout.progress(factor=view.progress, type="BAR", text=view.progress_text)
        text_lines(layout, view.message, icon=view.icon)


classes = (VIEW3D_PT_gt2gs_transfer,)

register, unregister = bpy.utils.register_classes_factory(classes)
