"""A job's folder in the batch's output folder (result, report, before/after strip), the hash of what the job
makes, and whether a finished job's folder already holds it (``--resume``). Pure Python: Blender's batch script
uses it too."""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

from .manifest import Job

REPORT, STRIP = "report.json", "before_after.png"
RUN_ONLY = ("threads", "device", "backend", "cache_dir", "weights_path")
"""Settings that say where and how fast a job runs, not what it makes: left out of the hash, so a batch resumed
on another machine (other threads, another rasterizer) keeps what it finished."""
STALE = ".*.tmp"
"""The temp files an atomic write leaves when its process is killed (``core.atomic``'s names)."""


@dataclass(frozen=True)
class Folder:
    """The files of one job's folder."""

    path: Path
    result: Path
    report: Path
    strip: Path

    def sweep(self) -> None:
        """Remove the temp files a killed attempt left (the folder is the batch's own)."""
        for stale in self.path.glob(STALE):
            stale.unlink(missing_ok=True)


def folder(out: Path, job: Job) -> Folder:
    """Where ``job``'s files go in the batch's output folder ``out``."""
    path = out / job.name
    return Folder(path, path / job.output, path / REPORT, path / STRIP)


def settings_hashes(jobs: list[Job]) -> list[str]:
    """Each job's settings hash: sha256 of what it makes (its inputs' contents, its preset and every setting
    that shapes the result, its result's name); each input file is read once."""
    digest = cache(_digest)
    hashes = []
    for job in jobs:
        config = {k: v for k, v in job.config().to_dict().items() if k not in RUN_ONLY}
        files = (("scene", job.scene), ("texture", job.texture), ("cameras", job.cameras))
        inputs = [(k, digest(str(p))) for k, p in files if p is not None]
        text = json.dumps([inputs, job.preset, config, job.output], sort_keys=True, default=str)
        hashes.append(hashlib.sha256(text.encode()).hexdigest())
    return hashes


def _digest(path: str) -> str:
    """sha256 of a file's content, or of a folder's listing (names, sizes, times); "missing" when absent (the job
    then fails alone and says so)."""
    digest = hashlib.sha256()
    if os.path.isdir(path):
        for root, _, files in sorted(os.walk(path)):
            for name in sorted(files):
                file = os.path.join(root, name)
                stat = os.stat(file)
                digest.update(f"{os.path.relpath(file, path)}:{stat.st_size}:{stat.st_mtime_ns}\n".encode())
        return digest.hexdigest()
    try:
        with open(path, "rb") as f:
            while chunk := f.read(1 << 20):
                digest.update(chunk)
    except OSError:
        return "missing"
    return digest.hexdigest()


def finished(out: Path, job: Job, key: str) -> dict[str, Any] | None:
    """The report of ``job`` when its folder holds its result and a report made with settings hash ``key``, else
    None (the strip, which Blender's batch script does not make, is not asked for)."""
    files = folder(out, job)
    if not files.result.is_file():
        return None
    report = read_report(files.report)
    return report if report is not None and report.get("batch", {}).get("settings_hash") == key else None


def read_report(path: Path) -> dict[str, Any] | None:
    """A job's report, or None when it is missing or unreadable."""
    try:
        report = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return report if isinstance(report, dict) else None
