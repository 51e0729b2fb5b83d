"""Transfer Texture, Cancel and Preview Orientation.

``gt2gs.transfer_texture`` runs the worker (see ``blender/transfer_run.py``): invoked from the UI it
is modal, polled on a window-manager timer, *Esc* or *Cancel* stop it; executed (scripts, ``blender
-b``) it runs the same job synchronously. ``texture_path``, ``preset``, ``angle`` (degrees) and
``n_views`` (automatic views) override the panel's settings when given, so a script needs one line:
``bpy.ops.gt2gs.transfer_texture(texture_path="wood.jpg", preset="preview")``.
"""

from __future__ import annotations

import time

import bpy
from bpy.props import FloatProperty, IntProperty, StringProperty

from ..blender import transfer_run
from ..blender.job import DONE, ERROR, RUNNING
from ..core.transfer.config import SETTINGS
from ..core.transfer.presets import PRESETS, preset
from . import machine

TIMER_S = 0.25
HEADLESS_TICK_S = 0.1
HEADLESS_STEP_PERCENT = 5
"""Headless runs print a progress line at every stage and every 5 % of the run."""


class RunOverrides:
    """Keyword properties that override the panel's settings when a script sets them."""

    texture_path: StringProperty(
        name="Texture",
        subtype="FILE_PATH",
        options={"SKIP_SAVE"},
        description="Texture file (default: the panel's texture)",
    )
    preset: StringProperty(
        name="Preset", options={"SKIP_SAVE"}, description=f"One of {', '.join(PRESETS)} (default: the panel's preset)"
    )
    angle: FloatProperty(
        name="Orientation",
        options={"SKIP_SAVE"},
        min=SETTINGS["angle"].min,
        max=SETTINGS["angle"].max,
        description="Texture angle in the first view, degrees (default: the panel's)",
    )
    n_views: IntProperty(
        name="Views",
        options={"SKIP_SAVE"},
        min=int(SETTINGS["n_views"].min),
        soft_max=int(SETTINGS["n_views"].soft_max),
        description="Use this many automatic views (default: the panel's views)",
    )

    def overrides(self) -> dict:
        """The properties the caller set, by the names ``TransferRun.start`` takes."""
        return {
            name: getattr(self, name)
            for name in ("texture_path", "preset", "angle", "n_views")
            if self.properties.is_property_set(name)
        }

    def check_preset(self) -> str | None:
        """Why the preset a script named cannot run (None: none named, or a known one)."""
        if not self.properties.is_property_set("preset"):
            return None
        try:
            preset(self.preset)
        except ValueError as exc:
            return str(exc)
        return None


def _start(op, context, kind: str) -> transfer_run.TransferRun | None:
    """Start a run, reporting why not when it cannot start."""
    problem = op.check_preset()
    if problem:
        op.report({"ERROR"}, problem)
        return None
    try:
        return transfer_run.TransferRun.start(context, op.overrides(), kind)
    except transfer_run.RunError as exc:
        op.report({"ERROR"}, str(exc))
        return None
    except ImportError as exc:
        op.report(
            {"ERROR"},
            f"GT² needs its Python dependencies ({exc.name or exc} is missing): install them "
            "in the extension's preferences",
        )
        return None


def _print_progress(status, shown: tuple | None) -> tuple | None:
    """Print a progress line (stage, percent, time left) when the stage or the next 5 % is reached; what was shown."""
    if status.state != RUNNING:
        return shown
    key = (status.stage, int(status.fraction * 100) // HEADLESS_STEP_PERCENT)
    if key != shown:
        print(f"gt2gs: {transfer_run.progress_text(status)}", flush=True)
    return key


def _end(op, run: transfer_run.TransferRun) -> set[str]:
    """Clean up, report the outcome, and the operator's return value for it."""
    outcome = run.finish()
    if run.kind == "transfer" and not bpy.app.background:
        machine.check()  # a first run builds the kernel (and may find weights): the preferences show it
    level = {"DONE": "INFO", "CANCELLED": "WARNING"}.get(outcome.state, "ERROR")
    what = "Texture transfer" if run.kind == "transfer" else "Orientation preview"
    message = f"failed: {outcome.message}" if outcome.state == ERROR else outcome.message
    op.report({level}, f"{what} {message}" + (f": {outcome.result}" if outcome.result else ""))
    return {"FINISHED"} if outcome.state == DONE else {"CANCELLED"}


class GT2GS_OT_transfer_texture(RunOverrides, bpy.types.Operator):
    """Re-texture the splat object with the texture photo (GT²-GS); runs in a separate process"""

    bl_idname = "gt2gs.transfer_texture"
    bl_label = "Transfer Texture"
    bl_options = {"UNDO"}  # not REGISTER: the redo panel would run the whole job again, synchronously

    _run: transfer_run.TransferRun | None = None
    _timer = None

    @classmethod
    def poll(cls, context):
        if "transfer" in transfer_run.ACTIVE:
            cls.poll_message_set("A texture transfer is running")
            return False
        return transfer_run.polled_target(cls, context) is not None

    def execute(self, context):
        run = _start(self, context, "transfer")
        if run is None:
            return {"CANCELLED"}
        shown = None
        try:
            while not (status := run.tick(context)).finished:
                shown = _print_progress(status, shown)
                time.sleep(HEADLESS_TICK_S)
        except BaseException:  # Ctrl+C or a bug: stop the worker and remove its files before passing it on
            run.cancel()
            run.finish()
            raise
        return _end(self, run)

    def invoke(self, context, event):
        if bpy.app.background or context.window is None:
            return self.execute(context)
        self._run = _start(self, context, "transfer")
        if self._run is None:
            return {"CANCELLED"}
        self._timer = context.window_manager.event_timer_add(TIMER_S, window=context.window)
        context.window_manager.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        run = self._run
        if (event.type == "ESC" and event.value == "PRESS") or run.cancel_requested:
            run.cancel()
        elif event.type != "TIMER":
            return {"PASS_THROUGH"}
        status = run.tick(context)
        machine.redraw(context)
        if not status.finished:
            return {"PASS_THROUGH"}
        context.window_manager.event_timer_remove(self._timer)
        return _end(self, run)


class GT2GS_OT_cancel_transfer(bpy.types.Operator):
    """Stop the running texture transfer; the scene stays as it was"""

    bl_idname = "gt2gs.cancel_transfer"
    bl_label = "Cancel"

    @classmethod
    def poll(cls, context):
        return "transfer" in transfer_run.ACTIVE

    def execute(self, context):
        transfer_run.ACTIVE["transfer"].cancel_requested = True  # the modal operator stops it on its next tick
        return {"FINISHED"}


class GT2GS_OT_preview_orientation(RunOverrides, bpy.types.Operator):
    """Show how the texture lies on the first view at the chosen angle (a quick render, no optimisation)"""

    bl_idname = "gt2gs.preview_orientation"
    bl_label = "Preview Orientation"

    @classmethod
    def poll(cls, context):
        return transfer_run.polled_target(cls, context) is not None

    def execute(self, context):
        run = _start(self, context, "preview")
        if run is None:
            return {"CANCELLED"}
        run.job.wait()
        run.tick(context)
        return _end(self, run)

    def invoke(self, context, event):
        if bpy.app.background or context.window is None:
            return self.execute(context)
        run = _start(self, context, "preview")
        if run is None:
            return {"CANCELLED"}

        def poll_preview() -> float | None:
            if transfer_run.ACTIVE.get("preview") is not run:
                return None  # superseded by a newer preview, which finished this one
            if run.tick(bpy.context).finished:
                run.finish()
                machine.redraw(bpy.context)
                return None
            return TIMER_S

        bpy.app.timers.register(poll_preview, first_interval=TIMER_S)
        return {"FINISHED"}


classes = (GT2GS_OT_transfer_texture, GT2GS_OT_cancel_transfer, GT2GS_OT_preview_orientation)


def register() -> None:
    for cls in classes:
        bpy.utils.register_class(cls)


def unregister() -> None:
    for run in list(transfer_run.ACTIVE.values()):
        run.cancel()
        run.finish()
    transfer_run.release_previews()
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
