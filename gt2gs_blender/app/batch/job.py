"""One job of a batch, as a worker runs it: read the inputs, re-texture, write the result, the report (with the
job's settings hash) and the before/after strip into the job's folder, all or nothing.

An error in the job's own inputs or settings (a bad texture, views that miss the scene) is its outcome: running
it again would change nothing. Anything else (a full disk, a crash, a lost worker) is raised for the scheduler to
retry.
"""

from __future__ import annotations

import json
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from ...core.atomic import all_or_nothing, atomic_write, check_outputs
from ...core.cameras.files import load_views
from ...core.errors import GT2GSError
from ...core.progress import Cancelled
from ...core.scene.files import read_scene
from ..jobs import read_texture, run_transfer, write_before_after
from .manifest import PATHS, Job
from .outputs import folder


@dataclass(frozen=True)
class Outcome:
    """How a job ended on its worker: ``done`` or ``failed`` (with the one-line error), in ``seconds``."""

    name: str
    status: str
    seconds: float
    error: str = ""
    notes: tuple[str, ...] = ()
    """The warnings the job raised on its worker (what a format dropped), for the batch to show as its own."""


def run_job(
    job: Job,
    out: Path,
    key: str,
    *,
    threads: int,
    device: str = "auto",
    cancel: Callable[[], bool] | None = None,
    batch: dict | None = None,
) -> Outcome:
    """Run ``job`` into its folder in ``out`` with ``threads`` CPU threads on ``device``; ``key`` is its settings
    hash, kept in the report for ``--resume``, with the ``batch`` facts (the worker) beside it. Raises
    :class:`Cancelled` when ``cancel()`` says so, and errors worth a retry."""
    start = time.monotonic()
    with warnings.catch_warnings(record=True) as raised:
        warnings.simplefilter("always")
        try:
            _run(job, out, key, threads, device, cancel, batch or {})
        except Cancelled:
            raise
        except (GT2GSError, ValueError) as exc:
            return Outcome(job.name, "failed", time.monotonic() - start, one_line(exc), _notes(raised))
    return Outcome(job.name, "done", time.monotonic() - start, notes=_notes(raised))


def _notes(raised: list[warnings.WarningMessage]) -> tuple[str, ...]:
    """The user warnings among ``raised``, one line each, once each (library deprecations say nothing to a user)."""
    lines = (" ".join(str(w.message).split()) for w in raised if issubclass(w.category, UserWarning))
    return tuple(dict.fromkeys(lines))


def _run(
    job: Job, out: Path, key: str, threads: int, device: str, cancel: Callable[[], bool] | None, batch: dict
) -> None:
    files = folder(out, job)
    if files.path.is_dir():
        files.sweep()
    config = job.config(threads=threads, device=device)
    scene = read_scene(job.scene)
    texture = read_texture(job.texture)
    views = load_views(job.cameras) if job.cameras is not None else None
    outputs = [("result", files.result), ("report", files.report), ("strip", files.strip)]
    inputs = [(what, getattr(job, what)) for what in PATHS]
    check_outputs(outputs, inputs, new_folders=[files.path])
    with all_or_nothing([path for _, path in outputs], new_folders=[files.path]):
        result = run_transfer(
            scene,
            texture,
            views,
            config,
            files.result,
            cancel=cancel,
            scene_name=job.scene,
            views_name=None if job.cameras is None else str(job.cameras),
        )
        report = {**result.report, "batch": {**batch, "job": job.name, "settings_hash": key, "where": job.where}}
        atomic_write(files.report, json.dumps(report, indent=1, default=str))
        write_before_after(files.strip, scene, result.scene, texture, views, config.up, config.view_kind)


def one_line(exc: BaseException) -> str:
    """An error as one line (OSErrors name their file)."""
    if isinstance(exc, OSError) and exc.filename is not None and exc.strerror:
        text = f"{exc.filename}: {exc.strerror}"
    else:
        text = str(exc) or type(exc).__name__
    return " ".join(text.split())
