"""What a run would use on this machine (weights, rasterizer, compiler, CUDA, kernel cache), as the worker sees it.

torch never loads into Blender, so ``app/machine.py`` runs in a process of the worker's Python and prints
what it found; ``start`` runs it in a background thread (the UI never waits), ``probe`` runs it and waits
(a transfer that must know whether CUDA is there). The last answer is in ``current()``, for the
preferences and the panel. bpy-free, like ``job.py``.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import threading
from dataclasses import dataclass, field
from typing import Any

from ..core.transfer.presets import GPU_PRESETS, gpu_preset_problem
from .job import PACKAGE_DIR, worker_env, worker_python

MODULE = f"{PACKAGE_DIR.name}.app.machine"
PROBE_TIMEOUT_S = 180.0
DOWNLOAD_TIMEOUT_S = 3600.0
MACHINE_SETTINGS = ("weights_path", "features", "backend", "device")
"""The preferences that change what the probe finds."""


@dataclass
class MachineState:
    """The last probe's answer (``info``), why it failed (``error``), and whether one runs now."""

    info: dict[str, Any] | None = None
    error: str | None = None
    running: str | None = None
    """None, ``"probe"`` or ``"download"`` while that runs."""
    settings: dict[str, Any] = field(default_factory=dict)
    packages: dict[str, dict[str, str | None]] | None = None
    """Each required package as the last check imported it in the worker's Python (version or error)."""


_state = MachineState()
_lock = threading.Lock()


def current() -> MachineState:
    """The last probe's outcome (empty before the first)."""
    return _state


def command(settings: dict[str, Any], download: bool = False) -> list[str]:
    """The probe's command line for these machine settings (``weights_path``, ``features``, ``backend``,
    ``device``; missing ones: the engine's defaults)."""
    args = [worker_python(), "-m", MODULE]
    for name in MACHINE_SETTINGS:
        if settings.get(name) is not None:
            args += [f"--{name.removesuffix('_path')}", str(settings[name])]
    return [*args, "--download"] if download else args


def probe(
    settings: dict[str, Any], deps_dir: str | None, download: bool = False
) -> tuple[dict[str, Any] | None, str | None]:
    """(info, None) from a probe process, or (None, why it failed); stores it as ``current()``."""
    timeout = DOWNLOAD_TIMEOUT_S if download else PROBE_TIMEOUT_S
    try:
        result = subprocess.run(
            command(settings, download),
            env=worker_env(deps_dir),
            capture_output=True,
            text=True,
            timeout=timeout,
            cwd=os.path.expanduser("~"),
        )
    except (OSError, subprocess.SubprocessError) as exc:
        answer, error = {}, f"the worker's Python could not run ({type(exc).__name__}: {exc})"
    else:
        answer, error = _answer(result)
    info = None if error else answer
    with _lock:
        _state.info = info if info is not None else _state.info
        _state.packages = answer.get("packages", _state.packages)
        _state.error, _state.running, _state.settings = error, None, dict(settings)
    return info, error


def _answer(result: subprocess.CompletedProcess) -> tuple[dict[str, Any], str | None]:
    """The probe's JSON object and None, or what it said (or {}) and why it failed."""
    lines = [line for line in result.stdout.splitlines() if line.startswith("{")]
    try:
        answer = json.loads(lines[-1]) if lines else None
    except ValueError:
        answer = None
    if isinstance(answer, dict):
        return answer, (str(answer["error"]) if "error" in answer else None)
    cause = error_line(result.stderr)
    return {}, f"the machine check exited with status {result.returncode}" + (f": {cause}" if cause else "")


def error_line(stderr: str) -> str | None:
    """The line of a Python traceback that names the error (the last ``SomeError: ...`` line, not the end of a
    long message), else the last line."""
    lines = [line.strip() for line in stderr.splitlines() if line.strip()]
    named = [line for line in lines if re.match(r"^[A-Za-z_][\w.]*(Error|Exception|Interrupt|Exit)\b", line)]
    return (named or lines or [None])[-1]


def start(settings: dict[str, Any], deps_dir: str | None, download: bool = False) -> bool:
    """Run the probe (or the weights download, then the probe) in a background thread; False if one runs."""
    with _lock:
        if _state.running is not None:
            return False
        _state.running = "download" if download else "probe"
    threading.Thread(target=probe, args=(settings, deps_dir, download), daemon=True).start()
    return True


def gpu_problem(preset: str, device: str, state: MachineState) -> str | None:
    """Why the GPU-only ``preset`` cannot run with the ``device`` preference on this machine; None when it can
    or while it is not known yet (no probe has answered)."""
    if preset not in GPU_PRESETS:
        return None
    if device == "cpu":
        return gpu_preset_problem(preset, False).replace("no CUDA GPU was found", "the Device preference is CPU")
    if state.info is None:
        return None
    return gpu_preset_problem(preset, bool(state.info.get("cuda")))
