"""A worker process seen from Blender: start it, poll it without blocking, cancel it, clean up after it.

bpy-free (plain subprocess and threads), so the modal operator, the headless operator and tests drive the same
object. The worker (``app/worker.py``) runs under ``worker_python()`` - Blender's own Python inside Blender,
unless ``GT2GS_WORKER_PYTHON`` names another - with the extension's dependency folder first on ``PYTHONPATH``.
Its JSON-line events are read by a thread into a queue, so ``poll()`` never waits on the pipe. Every file of a
job lives in one temporary folder, removed by ``cleanup()`` once the process has ended.
"""

from __future__ import annotations

import atexit
import collections
import json
import os
import queue
import shutil
import subprocess
import sys
import tempfile
import threading
import time
import weakref
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from ..app.deps import worker_pythonpath
from ..app.protocol import EXIT_CANCELLED, Event, JobSpec
from ..core.errors import MEMORY_ADVICE

PACKAGE_DIR = Path(__file__).resolve().parents[1]
"""The extension's package folder; the worker is imported from its parent under the same name."""
WORKER_MODULE = f"{PACKAGE_DIR.name}.app.worker"
WORKER_PYTHON_VARIABLE = "GT2GS_WORKER_PYTHON"
"""Names a Python with the engine's packages to run the worker and the machine check in (tests on a Blender
whose Python has no torch wheel here, developers with their own environment); unset: Blender's own."""
CANCEL_GRACE_S = 5.0
"""How long a cancelled worker may take to stop by itself before it is killed."""
STDERR_LINES = 40

IDLE, RUNNING, DONE, ERROR, CANCELLED = "IDLE", "RUNNING", "DONE", "ERROR", "CANCELLED"
FINISHED_STATES = (DONE, ERROR, CANCELLED)
SIGKILL = 9
"""Unblockable kill (POSIX): what the out-of-memory killer (Linux) and jetsam (macOS) send."""


@dataclass
class JobStatus:
    """What is known of a job now: state, progress and, when it has ended, its outcome."""

    state: str = IDLE
    fraction: float = 0.0
    stage: str = ""
    step: int = 0
    total: int = 0
    message: str = ""
    eta_s: float | None = None
    preview: str | None = None
    output: str | None = None
    report: dict[str, Any] | None = None
    error: str | None = None
    splats: tuple[int, int] | None = None
    """A preview's splat counts: what the run will start from, and the input's."""
    views: tuple[int, int, int, int] | None = None
    """A preview's run views: count, width, height, and the *Resolution* asked for (a dense capture: larger)."""

    @property
    def finished(self) -> bool:
        """Whether the job has ended, well or not (done, cancelled or failed)."""
        return self.state in FINISHED_STATES


def worker_python() -> str:
    """The Python the worker and the machine check run in."""
    return os.environ.get(WORKER_PYTHON_VARIABLE) or sys.executable


def worker_env(deps_dir: str | os.PathLike | None, env: dict[str, str] | None = None) -> dict[str, str]:
    """The environment of a process run with the worker's Python: the extension's dependencies and the
    package itself on ``PYTHONPATH``, unbuffered output."""
    env = dict(os.environ if env is None else env)
    env["PYTHONPATH"] = worker_pythonpath(PACKAGE_DIR.parent, deps_dir, env.get("PYTHONPATH"))
    env["PYTHONUNBUFFERED"] = "1"
    return env


class Job:
    """One worker run in its own temporary folder. Write the inputs into ``folder``, then ``start``."""

    def __init__(
        self, *, python: str | None = None, deps_dir: str | os.PathLike | None = None, env: dict[str, str] | None = None
    ) -> None:
        self.folder = Path(tempfile.mkdtemp(prefix="gt2gs_job_"))
        self.python = python or worker_python()
        self.deps_dir = deps_dir
        self.env = dict(os.environ if env is None else env)
        self.status = JobStatus()
        self.process: subprocess.Popen | None = None
        self._events: queue.Queue[dict | None] = queue.Queue()
        self._stderr: collections.deque[str] = collections.deque(maxlen=STDERR_LINES)
        self._readers: list[threading.Thread] = []
        self._cancel_requested = False
        _LIVE.add(self)

    def path(self, name: str) -> Path:
        """A file of this job (inside its folder)."""
        return self.folder / name

    def command(self) -> list[str]:
        """The worker's command line: its Python running the worker module on this job's ``job.json``."""
        return [self.python, "-m", WORKER_MODULE, str(self.path("job.json"))]

    def start(self, spec: JobSpec) -> None:
        """Write ``job.json`` (with the cancel file and preview folder of this job) and launch the worker."""
        replace(
            spec, cancel_file=spec.cancel_file or Path("cancel"), preview_dir=spec.preview_dir or Path("previews")
        ).save(self.path("job.json"))
        self.process = subprocess.Popen(
            self.command(),
            cwd=self.folder,
            env=worker_env(self.deps_dir, self.env),
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            encoding="utf-8",
            errors="replace",
        )
        self.status = JobStatus(state=RUNNING, stage="starting", message="starting the worker")
        self._readers = [
            threading.Thread(target=self._read_events, daemon=True),
            threading.Thread(target=self._read_stderr, daemon=True),
        ]
        for reader in self._readers:
            reader.start()

    def _read_events(self) -> None:
        for line in self.process.stdout:
            line = line.strip()
            if not line:
                continue
            try:
                event = json.loads(line)
            except ValueError:
                self._stderr.append(line)
                continue
            if isinstance(event, dict):
                self._events.put(event)
        self._events.put(None)  # end of stream

    def _read_stderr(self) -> None:
        for line in self.process.stderr:
            self._stderr.append(line.rstrip())

    def poll(self) -> JobStatus:
        """Apply every event that arrived (never waits); settle the state once the worker has exited."""
        if self.status.finished or self.process is None:
            return self.status
        ended = False
        while True:
            try:
                event = self._events.get_nowait()
            except queue.Empty:
                break
            if event is None:
                ended = True
                break
            self._apply(event)
        if ended:
            self._settle(self.process.wait())
        return self.status

    def _apply(self, event: dict[str, Any]) -> None:
        status = self.status
        kind = event.get("event")
        if kind == Event.PROGRESS:
            status.fraction = float(event.get("fraction") or 0.0)
            status.stage = str(event.get("stage") or "")
            status.step, status.total = int(event.get("step") or 0), int(event.get("total") or 0)
            status.message = str(event.get("message") or "")
            status.eta_s = event.get("eta_s")
            status.preview = event.get("preview") or status.preview
        elif kind == Event.DONE:
            status.output = event.get("output")
            if event.get("splats") and event.get("scene_splats"):
                status.splats = int(event["splats"]), int(event["scene_splats"])
            if event.get("views") and event.get("resolution"):
                status.views = (*(int(v) for v in event["views"]), int(event["resolution"]))
            report = event.get("report")
            if report and os.path.isfile(report):
                with open(report, encoding="utf-8") as f:
                    status.report = json.load(f)
        elif kind == Event.ERROR:
            status.error = str(event.get("message") or "the worker failed")

    def _settle(self, code: int) -> None:
        """The final state from the exit status (and the events that explain it)."""
        for reader in self._readers:
            reader.join(timeout=1.0)
        status = self.status
        if self._cancel_requested or code == EXIT_CANCELLED:
            status.state, status.message = CANCELLED, "cancelled"
        elif code == 0 and status.output and status.error is None:
            status.state, status.fraction, status.message = DONE, 1.0, "done"
        else:
            status.state = ERROR
            if status.error is None:
                tail = [line for line in self._stderr if line.strip()][-3:]
                how = f"was killed by signal {-code}" if code < 0 else f"exited with status {code}"
                if code == -SIGKILL:
                    how += f" (SIGKILL, how the system stops a process when memory runs out: {MEMORY_ADVICE})"
                status.error = f"the worker process {how}" + (": " + " | ".join(tail) if tail else "")
            status.message = status.error

    def stderr_tail(self) -> list[str]:
        """The worker's last lines on stderr, for an error that says why it stopped."""
        return list(self._stderr)

    def cancel(self, grace_s: float = CANCEL_GRACE_S) -> JobStatus:
        """Ask the worker to stop (cancel file + SIGTERM), kill it after ``grace_s``; the state becomes CANCELLED."""
        self._cancel_requested = True
        if self.process is not None and self.process.poll() is None:
            self.path("cancel").touch()
            self.process.terminate()
            try:
                self.process.wait(timeout=grace_s)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        if self.process is not None and not self.status.finished:
            self._settle(self.process.wait())
        self.status.state = CANCELLED
        return self.status

    def wait(self, timeout_s: float | None = None, tick_s: float = 0.1) -> JobStatus:
        """Poll until the job ends (the headless path); on timeout the job is cancelled."""
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while not self.poll().finished:
            if deadline is not None and time.monotonic() > deadline:
                self.cancel()
                self.status.error = f"the job took longer than {timeout_s:.0f} s and was stopped"
                break
            time.sleep(tick_s)
        return self.status

    def cleanup(self) -> None:
        """Remove the job's folder (stopping the worker first if it still runs)."""
        if self.process is not None and self.process.poll() is None:
            self.cancel()
        for reader in self._readers:
            reader.join(timeout=2.0)
        for stream in (self.process.stdout, self.process.stderr) if self.process is not None else ():
            stream.close()
        shutil.rmtree(self.folder, ignore_errors=True)
        _LIVE.discard(self)


_LIVE: weakref.WeakSet[Job] = weakref.WeakSet()


@atexit.register
def _cleanup_live_jobs() -> None:
    """When Blender quits during a run: stop the worker and remove its folder."""
    for job in list(_LIVE):
        job.cleanup()
