"""Run a batch on Dask: a ``LocalCluster`` on this machine, or the cluster of a running scheduler.

Dask schedules the jobs on its workers, retries a job that raised (``retries``), re-runs a job whose worker died
(the scheduler's ``allowed-failures``, set to the same count on a local cluster), keeps a GPU job to a worker
that offers a ``GPU`` resource, and serves the dashboard. The rest is ours: the per-job thread count (so that the
jobs sharing a machine do not fight), the start lines (each job logs an event that this process subscribes to),
``--resume``, a clean Ctrl-C (a Dask ``Event`` each job polls, so it stops and writes nothing) and the summary.
This is the only module that imports dask.
"""

from __future__ import annotations

import contextlib
import importlib.util
import logging
import os
import queue
import signal
import time
import uuid
import warnings
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO
from urllib.parse import urlparse

import dask
import psutil
from distributed import Client, Event, KilledWorker, LocalCluster, as_completed, get_worker

from ...core.atomic import check_outputs
from ...core.errors import GT2GSError, out_of_memory_message
from .board import Board
from .job import Outcome, one_line, run_job
from .manifest import PATHS, Job, read_manifest
from .outputs import finished, folder, read_report, settings_hashes
from .sheet import CONTACT_SHEET, write_contact_sheet
from .summary import SUMMARY_CSV, SUMMARY_MD, Row, write_summary

TOPIC = "gt2gs-batch"
"""The Dask event topic the jobs' start events go to."""
MAX_THREADS = 4
"""Threads per job on a local cluster: a quarter of the cores, at most this, so that several jobs run at once."""
JOB_MEMORY = 2 * 2**30
"""Memory a local worker is given at least (a ``fast`` job on the donut peaks at 1.06 GB resident): fewer
workers when the machine has less per core."""
POLL_S, CANCEL_POLL_S, CANCEL_GRACE_S = 0.2, 1.0, 30.0
CONNECT_TIMEOUT = "10s"


@dataclass
class BatchResult:
    """A finished batch: one row per job in the manifest's order, and the summary files written."""

    rows: list[Row]
    files: list[Path]

    @property
    def failed(self) -> list[Row]:
        return [row for row in self.rows if row.status == "failed"]


def run_batch(
    manifest: str | os.PathLike | Sequence[Job],
    out: str | os.PathLike,
    *,
    scheduler: str | None = None,
    workers: int | None = None,
    threads: int | None = None,
    retries: int = 2,
    resume: bool = False,
    stream: TextIO | None = None,
) -> BatchResult:
    """Run every job of ``manifest`` (a .csv/.toml file, or jobs) into one folder each in ``out``; write the
    summary table and the contact sheet. ``scheduler``: a running Dask scheduler's address (else a local
    cluster of ``workers`` workers, each job with ``threads`` CPU threads); ``retries``: more tries for a job
    that raised or whose worker died; ``resume``: keep the jobs whose folder holds their result made with the
    same settings. Failed jobs are rows, not exceptions; Ctrl-C cancels the running jobs, writes the summary of
    what finished and raises KeyboardInterrupt."""
    jobs = read_manifest(manifest) if isinstance(manifest, (str, os.PathLike)) else list(manifest)
    if scheduler is not None and workers is not None:
        raise GT2GSError("--workers sizes the local cluster; a running scheduler's cluster has its own workers")
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise GT2GSError(f"{out}: the batch's output folder is a file; name a folder")
    _check(out, jobs)
    keys = settings_hashes(jobs)
    rows: dict[str, Row] = {}
    for job, key in zip(jobs, keys):
        report = finished(out, job, key) if resume else None
        if report is not None:
            rows[job.name] = Row(job, "kept", report=report)
    todo = [(job, key) for job, key in zip(jobs, keys) if job.name not in rows]
    interrupted: KeyboardInterrupt | None = None
    try:
        with contextlib.ExitStack() as stack:
            board = stack.enter_context(Board(len(jobs), 1, stream))
            for row in rows.values():
                board.end(row)
            if todo:  # else every job was kept: no cluster to start
                client, plan = stack.enter_context(_connect(scheduler, workers, threads, retries, [j for j, _ in todo]))
                board.slots = plan.slots
                out.mkdir(parents=True, exist_ok=True)  # once the cluster is up: a refused start leaves nothing
                board.say(plan.describe(client))
                interrupted = _run(client, plan, out, todo, retries, board, rows)
    finally:
        _tidy(out, jobs)
    ordered = [rows.get(job.name) or Row(job, "cancelled") for job in jobs]
    files = [*write_summary(out, ordered), write_contact_sheet(out, ordered)]
    if interrupted is not None:
        raise interrupted  # Ctrl-C, or the signal that stopped the command (it exits as that signal says)
    return BatchResult(ordered, files)


def _check(out: Path, jobs: list[Job]) -> None:
    """Refuse, before any work, outputs that would overwrite an input or cannot be written."""
    inputs = [(f"{what} of {job.where}", getattr(job, what)) for job in jobs for what in PATHS]
    outputs = [(f"the summary {n}", out / n) for n in (SUMMARY_CSV, SUMMARY_MD, CONTACT_SHEET)]
    for job in jobs:
        files = folder(out, job)
        outputs += [(f"the result of {job.where}", files.result), (f"the report of {job.where}", files.report)]
        outputs.append((f"the strip of {job.where}", files.strip))
    check_outputs(outputs, inputs, new_folders=[out, *(folder(out, job).path for job in jobs)])


@dataclass(frozen=True)
class Plan:
    """How the jobs run: the threads each job gets (per host), whether jobs ask for a GPU, how many at once."""

    threads: dict[str, int] | int
    gpu_jobs: str
    """"cuda": jobs set to device cuda ask for a GPU; "all": every job but the cpu ones (a local GPU machine)."""
    slots: int
    local: bool

    def needs_gpu(self, job: Job) -> bool:
        device = job.settings.get("device", "auto")
        return device == "cuda" or (self.gpu_jobs == "all" and device != "cpu")

    def describe(self, client: Client) -> str:
        """One line: where the batch runs, and the dashboard's address when one is up."""
        info = client.scheduler_info()
        where = "a local Dask cluster" if self.local else f"the Dask scheduler {client.scheduler.address}"
        each = f"{self.threads} CPU thread(s) per job" if isinstance(self.threads, int) else "threads by host"
        line = f"running on {where}: {len(info.get('workers', {}))} workers, {self.slots} jobs at once, {each}"
        if "dashboard" in info.get("services", {}) and client.run_on_scheduler(_has_bokeh):
            line += f"; dashboard: {client.dashboard_link}"
        return line


@contextlib.contextmanager
def _connect(
    scheduler: str | None, workers: int | None, threads: int | None, retries: int, jobs: list[Job]
) -> Iterator[tuple[Client, Plan]]:
    """A client of the given scheduler, or of a local cluster sized for this machine, and the batch's plan."""
    if scheduler is not None:
        try:
            client = Client(scheduler, timeout=CONNECT_TIMEOUT)
        except OSError as exc:
            raise GT2GSError(f"cannot reach the Dask scheduler at {scheduler}: {one_line(exc)}") from None
        with client:
            yield client, _remote_plan(client, scheduler, threads, jobs)
        return
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    gpus = _local_gpus(jobs)
    if gpus == 0 and any(j.settings.get("device") == "cuda" for j in jobs):
        job = next(j for j in jobs if j.settings.get("device") == "cuda")
        raise GT2GSError(
            f"{job.where} asks for device cuda and this machine has no CUDA GPU: set device cpu, or "
            "run on a cluster with GPU workers (--scheduler)"
        )
    each = threads or max(1, min(MAX_THREADS, cores // 4))
    count = workers or (gpus or max(1, min(cores // each, psutil.virtual_memory().total // JOB_MEMORY)))
    if gpus and threads is None:
        each = max(1, cores // count)
    with (
        dask.config.set({"distributed.scheduler.allowed-failures": retries}),
        LocalCluster(
            n_workers=count,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            resources={"GPU": 1} if gpus else None,
            silence_logs=logging.ERROR,
            preload=[__name__],  # dask_setup below: Ctrl-C is this process's to handle
        ) as cluster,
        Client(cluster) as client,
    ):
        yield client, Plan(each, "all" if gpus else "cuda", count, local=True)


def _has_bokeh() -> bool:
    """Whether the scheduler's process can serve Dask's dashboard pages (they need bokeh, not installed here)."""
    return importlib.util.find_spec("bokeh") is not None


def _local_gpus(jobs: list[Job]) -> int:
    """CUDA GPUs on this machine, when a job may use one (torch is loaded only then)."""
    if all(job.settings.get("device") == "cpu" for job in jobs):
        return 0
    import torch

    return torch.cuda.device_count()


def _remote_plan(client: Client, scheduler: str, threads: int | None, jobs: list[Job]) -> Plan:
    """The plan on a running cluster: each job's threads share its host's cores among the worker threads there."""
    info = client.scheduler_info()["workers"]
    if not info:
        raise GT2GSError(f"the Dask scheduler at {scheduler} has no workers; start some with `dask worker {scheduler}`")
    if any(j.settings.get("device") == "cuda" for j in jobs) and not any(
        w.get("resources", {}).get("GPU") for w in info.values()
    ):
        raise GT2GSError(
            f"jobs ask for device cuda and no worker of {scheduler} offers a GPU: start GPU workers "
            f"with `dask worker {scheduler} --resources GPU=1`"
        )
    slots = sum(w["nthreads"] for w in info.values())
    if threads is not None:
        return Plan(threads, "cuda", slots, local=False)
    cores = client.run(os.cpu_count)
    per_host: dict[str, list[int]] = {}
    for address, worker in info.items():
        host = urlparse(address).hostname or address
        per_host.setdefault(host, [cores.get(address) or 1, 0])[1] += worker["nthreads"]
    return Plan({host: max(1, c // n) for host, (c, n) in per_host.items()}, "cuda", slots, local=False)


def _run(
    client: Client, plan: Plan, out: Path, todo: list[tuple[Job, str]], retries: int, board: Board, rows: dict
) -> KeyboardInterrupt | None:
    """Submit the jobs, show their starts and ends, fill ``rows``; the interrupt (Ctrl-C, or a stop signal) that
    cancelled the batch, None when it ran to its end."""
    batch = uuid.uuid4().hex
    events: queue.SimpleQueue = queue.SimpleQueue()
    client.subscribe_topic(TOPIC, events.put)
    futures = {
        client.submit(
            _task,
            job,
            str(out),
            key,
            batch,
            plan.threads,
            key=f"gt2gs-{job.name}-{key[:12]}-{batch[:8]}",
            retries=retries,
            resources={"GPU": 1} if plan.needs_gpu(job) else None,
            pure=False,
        ): job
        for job, key in todo
    }
    attempts: dict[str, int] = {}
    running: set[str] = set()
    pending = as_completed(futures)
    try:
        while not pending.is_empty():
            _take_events(events, batch, attempts, running, board)
            for future in pending.next_batch(block=False) if pending.has_ready() else ():
                job = futures[future]
                rows[job.name] = _row(future, job, out, attempts.get(job.name, 1))
                board.end(rows[job.name])
            time.sleep(POLL_S)
    except KeyboardInterrupt as stop:
        board.say("interrupted: cancelling the batch (running jobs stop and write nothing; one saving finishes)")
        finished_now = [f for f in futures if f.status == "finished" and futures[f].name not in rows]
        _cancel(client, batch, [f for f in futures if f not in finished_now])
        deadline = time.monotonic() + CANCEL_GRACE_S
        while running and time.monotonic() < deadline:  # each stops at its next look at the event, or finishes
            time.sleep(POLL_S)
            _take_events(events, batch, attempts, running, board)
        for future in finished_now:  # ended before the interrupt, not yet shown
            job = futures[future]
            rows[job.name] = _row(future, job, out, attempts.get(job.name, 1))
            board.end(rows[job.name])
        for job, key in todo:  # wrote its whole result while the cancel reached its worker: done, not cancelled
            report = None if job.name in rows else finished(out, job, key)
            if report is not None:
                seconds = float(report.get("seconds") or 0.0)
                rows[job.name] = Row(job, "done", attempts.get(job.name, 1), seconds, report=report)
                board.end(rows[job.name])
        return stop
    finally:
        client.unsubscribe_topic(TOPIC)
    return None


def _take_events(
    events: queue.SimpleQueue, batch: str, attempts: dict[str, int], running: set[str], board: Board
) -> None:
    """Take the jobs' start and end events that came in since the last call: print each start, count each job's
    attempts, and keep ``running`` the jobs started on a worker and not yet returned there."""
    while not events.empty():
        _, message = events.get()
        if not isinstance(message, dict) or message.get("batch") != batch:
            continue
        name = message["job"]
        if message.get("ended"):
            running.discard(name)
            continue
        attempts[name] = attempts.get(name, 0) + 1
        running.add(name)
        board.start(name, message["worker"], attempts[name])


def _row(future: Any, job: Job, out: Path, attempts: int) -> Row:
    """A finished future's row: the job's outcome, or why it failed after its retries."""
    if future.status == "finished":
        outcome: Outcome = future.result()
        for note in outcome.notes:  # shown here as the command's own warnings, not the worker's raw ones
            warnings.warn(f"{job.name}: {note}", stacklevel=1)
        report = read_report(folder(out, job).report) if outcome.status == "done" else None
        return Row(job, outcome.status, attempts, outcome.seconds, outcome.error, report or {})
    if future.status == "cancelled":
        return Row(job, "cancelled", attempts)
    exc = future.exception()
    if isinstance(exc, KilledWorker):
        message = "its worker died on every try while running it (out of memory? fewer --workers give each more)"
    else:
        memory = out_of_memory_message(exc)
        message = memory or (one_line(exc) if isinstance(exc, OSError) else f"{type(exc).__name__}: {one_line(exc)}")
    return Row(job, "failed", attempts, error=message)


def _cancel(client: Client, batch: str, futures: list) -> None:
    """Tell the running jobs to stop (they poll the batch's event) and drop the queued ones. A cancelled future
    leaves the scheduler at once, while its job runs on until it next looks at the event (or writes its whole
    result): its end event says when it returned."""
    Event(f"{TOPIC}-cancel-{batch}", client=client).set()
    client.cancel(futures)


def _tidy(out: Path, jobs: list[Job]) -> None:
    """Remove what killed or cancelled attempts left: temp files, and the job folders left empty."""
    for job in jobs:
        files = folder(out, job)
        if files.path.is_dir():
            files.sweep()
            with contextlib.suppress(OSError):
                files.path.rmdir()


def _task(job: Job, out: str, key: str, batch: str, threads: dict[str, int] | int) -> Outcome:
    """A job on its worker: announce the start, pick this worker's threads (and GPU), run it (stopping when the
    batch is cancelled), announce the end."""
    worker = get_worker()
    worker.log_event(TOPIC, {"batch": batch, "job": job.name, "worker": worker.address, "pid": os.getpid()})
    if isinstance(threads, dict):
        host = urlparse(worker.address).hostname or worker.address
        threads = threads.get(host) or max(1, (os.cpu_count() or 1) // worker.state.nthreads)
    _pick_gpu(worker.name)
    meta = {"worker": worker.address, "batch": batch}
    try:
        return run_job(job, Path(out), key, threads=threads, cancel=_cancelled(f"{TOPIC}-cancel-{batch}"), batch=meta)
    finally:
        worker.log_event(TOPIC, {"batch": batch, "job": job.name, "ended": True})


def _pick_gpu(name: Any) -> None:
    """On a local cluster of one worker per GPU, worker ``name`` (0, 1, ...) uses GPU ``name``."""
    import torch

    if isinstance(name, int) and torch.cuda.device_count() > 1:
        torch.cuda.set_device(name % torch.cuda.device_count())


def _cancelled(name: str) -> Any:
    """A cancel callable: whether the batch's event is set, asked of the scheduler at most once a second."""
    event, last = Event(name), {"at": 0.0, "set": False}

    def cancelled() -> bool:
        now = time.monotonic()
        if now - last["at"] > CANCEL_POLL_S:
            last["at"], last["set"] = now, event.is_set()
        return last["set"]

    return cancelled


def dask_setup(worker: Any) -> None:
    """A local worker's start (Dask's preload hook): ignore Ctrl-C, which the terminal sends to every process of
    the batch; the batch's own process cancels the jobs, and they stop cleanly."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
