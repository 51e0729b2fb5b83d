"""The GT² tab's Texture Transfer panel: settings, Preview Orientation, Transfer, Cancel, progress, report.

What it shows in each state (idle, running, done, error, cancelled) comes from ``transfer_view``, a
plain function the tests check; ``draw`` only lays that out.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import bpy

from ..blender import transfer_run
from ..blender.job import CANCELLED, DONE, ERROR, IDLE, RUNNING, JobStatus
from ..blender.transfer_run import progress_text
from ..core.transfer.config import IN_SCENE, PARTS, user_settings
from .sidebar import CATEGORY

FALLBACK_WARNING = (
    "no VGG weights were found, so a random network stood in and the result is not the method's: set Weights in "
    "the add-on preferences"
)
ICONS = {IDLE: "INFO", RUNNING: "TIME", DONE: "CHECKMARK", ERROR: "ERROR", CANCELLED: "CANCEL"}


@dataclass(frozen=True)
class TransferView:
    """Everything the panel shows besides the settings: state, buttons, progress bar, message, report."""

    state: str
    can_transfer: bool
    can_cancel: bool
    message: str
    icon: str
    progress: float | None = None
    progress_text: str = ""
    report_rows: list[tuple[str, str]] = field(default_factory=list)


def report_rows(report: dict[str, Any] | None, result: str | None, seconds: float = 0.0) -> list[tuple[str, str]]:
    """(label, value) rows summarising a run's report; ``seconds``: what the user waited, worker start included."""
    if not report:
        return [("Result", result)] if result else []
    width, height = report.get("image_size") or ("?", "?")
    rows = [
        ("Result", result or "-"),
        ("Time", f"{seconds:.0f} s (texture transfer {report.get('seconds', 0.0):.0f} s)"),
        ("Splats", f"{report.get('n_gaussians', 0):,}"),
        ("Views", f"{report.get('n_views', '?')} at {width}×{height}"),
        ("Device", str(report.get("device", "?"))),
    ]
    weights = report.get("weights") or {}
    rows.append(("Features", ("FALLBACK: " if weights.get("fallback") else "") + str(weights.get("spec", "?"))))
    metrics = report.get("metrics") or {}
    if metrics.get("texture_match") is not None and metrics.get("texture_match_start") is not None:
        rows.append(("Texture Match", f"{metrics['texture_match_start']:.3f} → {metrics['texture_match']:.3f}"))
    if metrics.get("ssim") is not None:
        rows.append(("SSIM", f"{metrics['ssim']:.3f}"))
    return rows


def transfer_view(target: str | None, running: JobStatus | None, last: transfer_run.Outcome | None) -> TransferView:
    """What the panel shows for a target object name (None: no splat selected), the running job's
    status (None: none runs) and the outcome of the last run."""
    if running is not None:
        text = progress_text(running)
        return TransferView(RUNNING, False, True, running.message or text, ICONS[RUNNING], running.fraction, text)
    can = target is not None
    if last is None:
        message = f"Ready: {target}" if can else "Select a Gaussian splat object"
        return TransferView(IDLE, can, False, message, ICONS[IDLE])
    rows = report_rows(last.report, last.result, last.seconds) if last.state == DONE else []
    message = {
        DONE: last.message[:1].upper() + last.message[1:],
        CANCELLED: "Cancelled; the scene is unchanged",
        ERROR: f"Failed: {last.message}",
    }.get(last.state, last.message)
    if last.state == DONE and used_fallback(last.report):
        message += f"; {FALLBACK_WARNING}"
        return TransferView(last.state, can, False, message, "ERROR", report_rows=rows)
    return TransferView(last.state, can, False, message, ICONS.get(last.state, "INFO"), report_rows=rows)


def used_fallback(report: dict[str, Any] | None) -> bool:
    """Whether a run's report says it used the random fallback network (no VGG weights were found)."""
    return bool(((report or {}).get("weights") or {}).get("fallback"))


def current_view(context) -> TransferView:
    """``transfer_view`` for the current context."""
    target = transfer_run.target_object(context)
    run = transfer_run.ACTIVE.get("transfer")
    return transfer_view(
        target.name if target else None, run.job.status if run else None, transfer_run.OUTCOMES.get("transfer")
    )


class VIEW3D_PT_gt2gs_transfer(bpy.types.Panel):
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
        row = layout.row(align=True)
        row.prop(settings, "texture_source", expand=True)
        layout.prop(settings, "texture_path" if settings.texture_source == "FILE" else "texture_image", text="")
        layout.prop(settings, "view_source")
        if settings.view_source == "AUTO":
            layout.prop(settings, "n_views")
        elif settings.view_source == "COLLECTION":
            layout.prop(settings, "camera_collection", text="")
        elif settings.view_source == "CAMERAS_JSON":
            layout.prop(settings, "cameras_json", text="")
        layout.prop(settings, "preset")
        row = layout.row(align=True)
        row.prop(settings, "angle")
        row.prop(settings, "auto_preview", text="", icon="FILE_REFRESH")
        layout.prop(settings, "texture_height")
        layout.prop(settings, "lambda_content")
        row = layout.row(align=True)
        row.prop(settings, "result_mode", expand=True)
        layout.prop(settings, "region_only")

        row = layout.row(align=True)
        row.operator("gt2gs.preview_orientation", icon="ORIENTATION_GIMBAL")
        row = layout.row(align=True)
        row.enabled = view.can_transfer
        row.operator("gt2gs.transfer_texture", icon="TEXTURE")
        if view.can_cancel:
            layout.operator("gt2gs.cancel_transfer", icon="CANCEL")
        if view.progress is not None:
            layout.progress(factor=view.progress, type="BAR", text=view.progress_text)
        layout.label(text=view.message, icon=view.icon)
        icon = transfer_run.preview_icon()
        if icon:
            layout.template_icon(icon_value=icon, scale=10.0)
        if view.report_rows:
            column = layout.box().column(align=True)
            for label, value in view.report_rows:
                split = column.split(factor=0.4)
                split.label(text=label)
                split.label(text=value)


MAIN_SETTINGS = ("n_views", "angle", "texture_height", "lambda_content")
"""Settings the main panel shows; every other scene setting is in its part's sub-panel."""


def part_panel(part: str, title: str) -> type:
    """A closed sub-panel listing the scene settings of one part of the method."""
    names = [name for name, meta, _ in user_settings(IN_SCENE) if meta.part == part and name not in MAIN_SETTINGS]

    def draw(self, context) -> None:
        column = self.layout.column()
        column.use_property_split = True
        column.use_property_decorate = False
        for name in names:
            column.prop(context.scene.gt2gs, name)

    return type(
        f"VIEW3D_PT_gt2gs_{part}",
        (bpy.types.Panel,),
        {
            "bl_space_type": "VIEW_3D",
            "bl_region_type": "UI",
            "bl_category": CATEGORY,
            "bl_label": title,
            "bl_parent_id": "VIEW3D_PT_gt2gs_transfer",
            "bl_options": {"DEFAULT_CLOSED"},
            "draw": draw,
            "__doc__": f"The {title} settings of the texture transfer",
        },
    )


PART_PANELS = tuple(
    part_panel(part, title)
    for part, title in PARTS.items()
    if any(meta.part == part and name not in MAIN_SETTINGS for name, meta, _ in user_settings(IN_SCENE))
)

classes = (VIEW3D_PT_gt2gs_transfer, *PART_PANELS)

register, unregister = bpy.utils.register_classes_factory(classes)
