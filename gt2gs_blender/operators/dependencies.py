"""Install dependencies: pip installs the engine packages pinned for Blender's Python into the extension's
user folder, then the machine check imports them in the worker's Python (versions alone do not say they load).

Runs pip in a subprocess polled by a timer, so Blender stays responsive during the download. Only
when Blender allows online access (the manifest declares the network permission).
"""

from __future__ import annotations

import importlib.metadata
import subprocess
import sys
import tempfile

import bpy

from ..app import deps
from ..blender import addon
from . import machine as machine_ops

POLL_S = 0.5


def install_commands(build: str, target: str) -> list[list[str]]:
    """The commands this button runs with Blender's Python: ensurepip when pip is absent, then pip install."""
    # pip's metadata, not find_spec("pip"): that makes setuptools' distutils hook stand down for the whole process
    has_pip = next(iter(importlib.metadata.distributions(name="pip")), None) is not None
    bootstrap = [] if has_pip else [[sys.executable, "-m", "ensurepip", "--upgrade"]]
    return [*bootstrap, deps.install_command(sys.executable, target, build)]


class GT2GS_OT_install_dependencies(bpy.types.Operator):
    """Download torch, numpy and OpenCV (pinned versions) with pip into the extension's user folder"""

    bl_idname = "gt2gs.install_dependencies"
    bl_label = "Install Dependencies"

    _commands: list[list[str]]
    _process: subprocess.Popen | None = None
    _log = None
    _timer = None

    @classmethod
    def poll(cls, context):
        if not bpy.app.online_access:
            cls.poll_message_set(f"Online access is disabled: {addon.ONLINE_ACCESS}")
            return False
        if addon.deps_dir() is None:
            cls.poll_message_set("Only the installed extension can install its dependencies")
            return False
        try:
            deps.pinned_packages()
        except ValueError as exc:
            cls.poll_message_set(f"This Blender's Python has {exc}")
            return False
        return True

    def invoke(self, context, event):
        prefs = addon.preferences(context)
        self._commands = install_commands(prefs.build if prefs else "CPU", addon.deps_dir(create=True))
        self._log = tempfile.TemporaryFile(mode="w+", encoding="utf-8")
        self._next()
        self._timer = context.window_manager.event_timer_add(POLL_S, window=context.window)
        context.window_manager.modal_handler_add(self)
        self.report({"INFO"}, "Installing the dependencies with pip (this can take several minutes)")
        return {"RUNNING_MODAL"}

    def _next(self) -> None:
        self._process = subprocess.Popen(
            self._commands.pop(0), stdin=subprocess.DEVNULL, stdout=self._log, stderr=subprocess.STDOUT
        )

    def modal(self, context, event):
        if event.type != "TIMER" or self._process.poll() is None:
            return {"PASS_THROUGH"}
        if self._process.returncode == 0 and self._commands:
            self._next()
            return {"PASS_THROUGH"}
        context.window_manager.event_timer_remove(self._timer)
        self._log.seek(0)
        lines = [line for line in self._log.read().splitlines() if line.strip()]
        self._log.close()
        if self._process.returncode != 0:
            self.report({"ERROR"}, "pip failed: " + (lines[-1] if lines else f"exit status {self._process.returncode}"))
            return {"CANCELLED"}
        machine_ops.check(context)
        self.report({"INFO"}, "Dependencies installed: checking that they load (What a Transfer Uses, below)")
        return {"FINISHED"}


classes = (GT2GS_OT_install_dependencies,)

register, unregister = bpy.utils.register_classes_factory(classes)
