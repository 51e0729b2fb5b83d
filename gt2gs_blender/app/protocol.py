"""The worker's protocol: the job file it reads, the JSON-line events it writes, its exit codes.
The one owner of both ends: the worker (``app/worker.py``) and Blender's side of it (``blender/job.py``,
``blender/transfer_run.py``) write and read the job file and the events through this module (numpy-free)."""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path
from typing import IO, Any

from ..core.errors import InputFileError

EXIT_DONE, EXIT_INTERNAL, EXIT_INPUT, EXIT_CANCELLED, EXIT_MEMORY = 0, 1, 2, 3, 4
"""The worker's exit status: done, a bug, an unusable input, cancelled, out of memory."""

KINDS = ("transfer", "preview")


class Event(StrEnum):
    """The name of each JSON-line event the worker writes (its ``"event"`` field)."""

    PROGRESS = "progress"
    DONE = "done"
    CANCELLED = "cancelled"
    ERROR = "error"


@dataclass(frozen=True)
class JobSpec:
    """A parsed job file; paths are absolute or relative to the job file's folder."""

    kind: str
    input: Path
    texture: Path
    output: Path
    views: Path | int | None = None
    preset: str = "fast"
    config: dict[str, Any] | None = None
    region: Path | None = None
    report: Path | None = None
    preview_dir: Path | None = None
    cancel_file: Path | None = None
    preview_size: int = 256
    input_name: str | None = None
    views_name: str | None = None

    @classmethod
    def load(cls, path: str | os.PathLike) -> JobSpec:
        """Read and check a job file; any problem is an InputFileError naming it."""
        path = Path(path)
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            raise InputFileError(path, f"cannot read the job file ({exc})") from None
        return cls.from_dict(data, path.parent, path)

    @classmethod
    def from_dict(cls, data: Any, base: Path = Path(), source: str | os.PathLike = "the job") -> JobSpec:
        """Check a job's JSON object; its relative paths are taken from ``base``; problems name ``source``."""
        if not isinstance(data, dict):
            raise InputFileError(source, "the job file must hold a JSON object")
        missing = [key for key in ("kind", "input", "texture", "output") if not data.get(key)]
        if missing:
            raise InputFileError(source, f"the job lacks {', '.join(missing)}")
        if data["kind"] not in KINDS:
            raise InputFileError(source, f"unknown job kind {data['kind']!r}; expected one of {', '.join(KINDS)}")
        unknown = set(data) - set(cls.__dataclass_fields__)
        if unknown:
            raise InputFileError(source, f"unknown job keys: {', '.join(sorted(unknown))}")

        def resolve(value: Any) -> Path | None:
            return None if value in (None, "") else base / Path(value)

        views = data.get("views")
        if isinstance(views, bool) or (views is not None and not isinstance(views, (int, str))):
            raise InputFileError(source, f"views must be a cameras file path or a count, got {views!r}")
        return cls(
            kind=data["kind"],
            input=resolve(data["input"]),
            texture=resolve(data["texture"]),
            output=resolve(data["output"]),
            views=resolve(views) if isinstance(views, str) else views,
            preset=data.get("preset") or "fast",
            config=dict(data.get("config") or {}),
            region=resolve(data.get("region")),
            report=resolve(data.get("report")),
            preview_dir=resolve(data.get("preview_dir")),
            cancel_file=resolve(data.get("cancel_file")),
            preview_size=int(data.get("preview_size") or 256),
            input_name=data.get("input_name") or None,
            views_name=data.get("views_name") or None,
        )

    def to_dict(self) -> dict[str, Any]:
        """The job as its file holds it: paths as strings (relative ones stay relative to the job file)."""
        return {
            name: str(value) if isinstance(value, Path) else value
            for name, value in ((f, getattr(self, f)) for f in self.__dataclass_fields__)
            if value is not None
        }

    def save(self, path: str | os.PathLike) -> None:
        """Write the job file the worker reads (:meth:`load`)."""
        Path(path).write_text(json.dumps(self.to_dict(), indent=1), encoding="utf-8")


class Events:
    """Writes one JSON object per line to the event stream, flushed at once."""

    def __init__(self, stream: IO[str]) -> None:
        self.stream = stream

    def __call__(self, event: Event, **fields: Any) -> None:
        self.stream.write(json.dumps({"event": event, **fields}) + "\n")
        self.stream.flush()
