"""Check Machine and Download Weights: what the preferences show of weights, rasterizer, compiler and CUDA.

Both run ``app/machine.py`` with the worker's Python in a background thread (``blender/machine.py``) and
redraw the preferences and the panel when it answers; the UI never waits. The machine is checked once
after Blender starts (not in background mode) and again after each transfer.
"""

from __future__ import annotations

import bpy

from ..blender import addon, machine, transfer_run

POLL_S = 0.5
START_DELAY_S = 1.0


def redraw(context=None) -> None:
    """Tag the 3D views and the preferences for a redraw: their panels show what a job or a check found."""
    for window in (context or bpy.context).window_manager.windows:
        for area in window.screen.areas:
            if area.type in ("VIEW_3D", "PREFERENCES"):
                area.tag_redraw()


def _wait_and_redraw() -> float | None:
    """Timer: redraw once the check has answered."""
    if machine.current().running is not None:
        return POLL_S
    redraw()
    return None


def check(context=None, download: bool = False) -> bool:
    """Start a machine check (or the weights download) for the preferences' settings; False if one runs."""
    started = machine.start(transfer_run.machine_settings(context or bpy.context), addon.deps_dir(), download)
    if started and not bpy.app.background:
        bpy.app.timers.register(_wait_and_redraw, first_interval=POLL_S)
    return started


class GT2GS_OT_check_machine(bpy.types.Operator):
    """Find again which weights, rasterizer, compiler and GPU a transfer would use"""

    bl_idname = "gt2gs.check_machine"
    bl_label = "Check Again"

    @classmethod
    def poll(cls, context):
        return machine.current().running is None

    def execute(self, context):
        check(context)
        return {"FINISHED"}


class GT2GS_OT_download_weights(bpy.types.Operator):
    """Download the paper's VGG-16 network weights (528 MB, from download.pytorch.org) into torch's cache"""

    bl_idname = "gt2gs.download_weights"
    bl_label = "Download Weights"

    @classmethod
    def poll(cls, context):
        if not bpy.app.online_access:
            cls.poll_message_set(f"Online access is disabled: {addon.ONLINE_ACCESS}")
            return False
        return machine.current().running is None

    def execute(self, context):
        check(context, download=True)
        self.report({"INFO"}, "Downloading the VGG-16 weights (528 MB) in the background")
        return {"FINISHED"}


classes = (GT2GS_OT_check_machine, GT2GS_OT_download_weights)


def _first_check() -> None:
    check()


def register() -> None:
    for cls in classes:
        bpy.utils.register_class(cls)
    if not bpy.app.background:
        bpy.app.timers.register(_first_check, first_interval=START_DELAY_S)


def unregister() -> None:
    if bpy.app.timers.is_registered(_first_check):
        bpy.app.timers.unregister(_first_check)
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
