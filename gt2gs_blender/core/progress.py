"""Progress and cancellation of any long engine run (transfer, fit, render): one event type.

Every run reports :class:`Progress` events to a plain callable; the front ends turn the same events
into a terminal bar (``app/progress.py``), the worker's JSON lines and Blender's progress bar. A
:class:`Tracker` times a run's stages, turns (stage, step) into an overall fraction and ETA by the
stages' expected shares of the time, and polls a cancel callable, raising :class:`Cancelled`.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np

from .errors import GT2GSError

ETA_AFTER = 0.02
"""No ETA before this fraction of the run is done: an early guess is mostly set-up time."""


class Cancelled(GT2GSError):
    """The run was cancelled by its caller; nothing was written."""


@dataclass
class Progress:
    """One progress report: ``fraction`` of the whole run done, ``eta_s`` seconds left (None at first)."""

    stage: str
    step: int
    total: int
    fraction: float
    eta_s: float | None
    message: str
    preview: np.ndarray | None = None  # (H,W,3) uint8 render of the first view, now and then


ProgressCallback = Callable[[Progress], None]


def format_eta(seconds: float) -> str:
    """``1:05`` for 65 seconds (minutes may exceed 59)."""
    seconds = max(0, round(seconds))
    return f"{seconds // 60}:{seconds % 60:02d}"


@dataclass
class Tracker:
    """Stage timing, progress fractions and cancellation for one run whose stages take ``weights``
    (stage -> expected share of the run's time, summing to 1)."""

    progress: ProgressCallback | None
    cancel: Callable[[], bool] | None
    weights: Mapping[str, float]
    what: str = "run"
    start: float = field(default_factory=time.perf_counter)
    seconds: dict[str, float] = field(default_factory=dict)
    stage: str = ""
    stage_start: float = field(default_factory=time.perf_counter)

    def begin(self, stage: str) -> None:
        """Start ``stage`` (after checking for a cancel) and report it."""
        self.check_cancel()
        self.stage, self.stage_start = stage, time.perf_counter()
        self.tell(0, 1, stage)

    def end(self) -> None:
        """Record the current stage's seconds."""
        self.seconds[self.stage] = time.perf_counter() - self.stage_start

    def check_cancel(self) -> None:
        """Raise :class:`Cancelled` when the caller asked to stop."""
        if self.cancel is not None and self.cancel():
            raise Cancelled(f"{self.what} cancelled")

    def tell(self, step: int, total: int, message: str, preview: np.ndarray | None = None) -> None:
        """Report ``step`` of ``total`` in the current stage."""
        if self.progress is None:
            return
        done = sum(share for stage, share in self.weights.items() if stage in self.seconds)
        fraction = min(1.0, done + self.weights[self.stage] * step / max(total, 1))
        elapsed = time.perf_counter() - self.start
        eta = elapsed * (1.0 - fraction) / fraction if fraction > ETA_AFTER else None
        self.progress(Progress(self.stage, step, total, fraction, eta, message, preview))
