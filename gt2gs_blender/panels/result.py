"""The Result sub-panel: how the last transfer ended - time, metrics, the weights it used, where the result is.

What it shows comes from ``result_view``, a plain function the tests check; ``draw`` only lays it out.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any

import bpy

from ..blender import transfer_run
from ..blender.job import DONE
from .sidebar import CATEGORY, text_lines, value_rows
from .transfer_panel import current_view

NO_RUN_TEXT = "No transfer yet: the outcome of the last one shows here"


@dataclass(frozen=True)
class ResultView:
    """The Result sub-panel's message, its icon and (label, value) rows."""

    message: str
    icon: str
    rows: list[tuple[str, str]] = field(default_factory=list)


def weights_text(report: dict[str, Any]) -> str:
    """Which feature network and weights file a run used, loud about the random fallback."""
    weights = report.get("weights") or {}
    if weights.get("fallback"):
        return "RANDOM network (no VGG weights found)"
    file = weights.get("weights_file")
    return f"{weights.get('spec', '?')}" + (f" ({os.path.basename(file)})" if file else "")


def result_location(name: str | None, mode: str) -> str:
    """Where the result of a run is: the object (new, or changed in place) and its collection (the panel's message
    says where a new one's hidden original is)."""
    if not name:
        return "-"
    obj = bpy.data.objects.get(name)
    if obj is None:
        return f"{name!r} (no longer in the file)"
    where = obj.users_collection[0].name if obj.users_collection else "no collection"
    if mode == "IN_PLACE":
        return f"changed in place {name!r} in {where!r}"
    return f"new object {name!r} in {where!r}"


def report_rows(
    report: dict[str, Any] | None,
    result: str | None,
    seconds: float = 0.0,
    mode: str = "NEW",
) -> list[tuple[str, str]]:
    """(label, value) rows summarising a run's report; ``seconds``: what the user waited, worker start included;
    ``mode``: how the result was applied."""
    if not report:
        return [("Result", result_location(result, mode))] if result else []
    width, height = report.get("image_size") or ("?", "?")
    rows = [
        ("Result", result_location(result, mode)),
        ("Time", f"{seconds:.0f} s (texture transfer {report.get('seconds', 0.0):.0f} s)"),
        ("Splats", f"{report.get('n_gaussians', 0):,}"),
        ("Views", f"{report.get('n_views', '?')} at {width}×{height}"),
        ("Device", str(report.get("device", "?"))),
        ("Weights", weights_text(report)),
    ]
    metrics = report.get("metrics") or {}
    if metrics.get("texture_match") is not None and metrics.get("texture_match_start") is not None:
        rows.append(("Texture Match", f"{metrics['texture_match_start']:.3f} → {metrics['texture_match']:.3f}"))
    if metrics.get("object_ssim") is not None:
        rows.append(("Scene Kept (SSIM)", f"{metrics['object_ssim']:.3f}"))
    if metrics.get("object_ssim_blurred") is not None:
        rows.append(("Parts Kept (SSIM)", f"{metrics['object_ssim_blurred']:.3f}"))
    if metrics.get("ssim") is not None:
        rows.append(("Frame SSIM (Paper)", f"{metrics['ssim']:.3f}"))
    if metrics.get("preview_ssim") is not None:
        rows.append(("Like the Preview (SSIM)", f"{metrics['preview_ssim']:.3f}"))
    return rows


def result_view(last: transfer_run.Outcome | None, message: str, icon: str) -> ResultView:
    """The Result sub-panel for the last transfer's outcome: its rows, or when there are none (a failed or cancelled
    run) the main panel's message and icon for it."""
    if last is None:
        return ResultView(NO_RUN_TEXT, "INFO")
    rows = report_rows(last.report, last.result, last.seconds, last.mode) if last.state == DONE else []
    return ResultView("" if rows else message, icon, rows)


class VIEW3D_PT_gt2gs_result(bpy.types.Panel):
    """Where the last transfer's result is, how long it took and how much of the scene it kept"""

    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = CATEGORY
    bl_label = "Result"
    bl_parent_id = "VIEW3D_PT_gt2gs_transfer"

    def draw(self, context):
        main = current_view(context)
        view = result_view(transfer_run.OUTCOMES.get("transfer"), main.message, main.icon)
        if view.message:
            text_lines(self.layout, view.message, icon=view.icon)
        value_rows(self.layout, view.rows)


classes = (VIEW3D_PT_gt2gs_result,)

register, unregister = bpy.utils.register_classes_factory(classes)
