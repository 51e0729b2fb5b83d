"""Progress on the terminal: the engine's :class:`~..core.progress.Progress` events as one tqdm bar.

The same events feed the worker's JSON lines (``worker.py``) and Blender's progress bar; this is
only their terminal face. On a terminal the bar is redrawn in place; in a log (no terminal) one line
is written when the stage changes and at most every ``LOG_EVERY_S`` seconds otherwise.
"""

from __future__ import annotations

import sys
import time
from typing import TextIO

from tqdm import tqdm

from ..core.progress import Progress, format_eta

STEPS = 1000
"""The bar counts thousandths of the whole run (events carry a fraction, not a count)."""
LOG_EVERY_S = 30.0


class TerminalProgress:
    """A progress callback that draws the run on ``stream``; use as a context manager to close it."""

    def __init__(self, what: str, stream: TextIO | None = None) -> None:
        self.stream = sys.stderr if stream is None else stream
        self.tty = self.stream.isatty()
        self.bar = (
            tqdm(
                total=STEPS,
                desc=what,
                file=self.stream,
                leave=True,
                dynamic_ncols=True,
                bar_format="{desc} {bar} {percentage:3.0f}% {postfix}",
            )
            if self.tty
            else None
        )
        self.stage: str | None = None
        self.last = 0.0

    def __call__(self, p: Progress) -> None:
        """Show one event."""
        if self.bar is not None:
            self.bar.n = min(STEPS, int(p.fraction * STEPS))
            eta = "" if p.eta_s is None else f"  ETA {format_eta(p.eta_s)}"
            self.bar.set_postfix_str(f"{p.stage} {p.step}/{p.total}{eta}", refresh=False)
            self.bar.refresh()
        elif p.stage != self.stage or time.monotonic() - self.last > LOG_EVERY_S:
            self.stream.write(f"{p.fraction:4.0%} {p.message}\n")
            self.stream.flush()
            self.last = time.monotonic()
        self.stage = p.stage

    def close(self) -> None:
        """End the bar's line."""
        if self.bar is not None:
            self.bar.close()

    def __enter__(self) -> TerminalProgress:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
