"""A batch's progress on the terminal: one line per job start and end, and an overall bar (jobs done, failed,
ETA) that tqdm redraws in place on a terminal; in a log, each end line carries the count and the ETA."""

from __future__ import annotations

import sys
import time
from typing import TextIO

from tqdm import tqdm

from ...core.progress import format_eta
from .summary import Row


class Board:
    """Progress of ``total`` jobs run ``slots`` at a time; a context manager that closes the bar."""

    def __init__(self, total: int, slots: int, stream: TextIO | None = None) -> None:
        self.stream = sys.stdout if stream is None else stream
        self.total, self.slots = total, max(1, slots)
        self.done = self.failed = 0
        self.seconds: list[float] = []
        self.started = time.monotonic()
        self.bar = (
            tqdm(
                total=total,
                desc="batch",
                file=self.stream,
                leave=True,
                dynamic_ncols=True,
                bar_format="{desc} {bar}{postfix}",  # our count and ETA (jobs take minutes, not iterations/s)
            )
            if self.stream.isatty()
            else None
        )

    def say(self, line: str) -> None:
        """One line above the bar."""
        if self.bar is not None:
            self.bar.write(line, file=self.stream)
        else:
            self.stream.write(line + "\n")
            self.stream.flush()

    def start(self, name: str, worker: str, attempt: int) -> None:
        """A job started on ``worker`` (its ``attempt``-th try)."""
        again = f" (attempt {attempt})" if attempt > 1 else ""
        self.say(f"start  {name} on {worker}{again}")

    def end(self, row: Row) -> None:
        """A job ended: its line, then the bar (or, in a log, the count and ETA on the same line)."""
        self.done += row.status in ("done", "kept")
        self.failed += row.status == "failed"
        if row.status == "done":
            self.seconds.append(row.seconds)
        what = f"{row.status:<6} {row.job.name}"
        detail = f" in {row.seconds:.1f}s" if row.status == "done" else f": {row.error}" if row.error else ""
        self.say(f"{what}{detail}" + ("" if self.bar is not None else f"  [{self.status()}]"))
        if self.bar is not None:
            self.bar.update(1)
            self.bar.set_postfix_str(self.status(), refresh=True)

    def status(self) -> str:
        """'5/8 jobs, 1 failed, ETA 2m 10s'."""
        finished = self.done + self.failed
        text = f"{finished}/{self.total} jobs, {self.failed} failed"
        eta = self.eta()
        return text if eta is None else f"{text}, ETA {format_eta(eta)}"

    def eta(self) -> float | None:
        """Seconds left: the jobs left times the mean job's time, over the jobs that run at once."""
        left = self.total - self.done - self.failed
        if not self.seconds or left == 0:
            return None
        return left * (sum(self.seconds) / len(self.seconds)) / min(self.slots, left)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()

    def __enter__(self) -> Board:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
