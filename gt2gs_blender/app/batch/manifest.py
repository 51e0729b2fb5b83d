"""A batch's manifest: its jobs (scene, texture, preset, settings, output name), read from a CSV or TOML file.

CSV: a header row; the columns ``scene`` and ``texture`` are required, ``preset``, ``output`` (a file name in the
batch's output folder) and ``cameras`` optional, any other column a transfer setting's name; an empty cell keeps
the preset's value. TOML: ``preset`` and a ``[settings]`` table for every job, ``[[job]]`` tables (one job each)
and ``[[product]]`` tables (one job per combination of their lists: scenes x textures x angles). Paths are
relative to the manifest's folder. Every job's settings are checked here, before any work: a mistake is one
line naming the manifest and the row or table. Pure Python (and numpy through the settings): Blender's batch
script reads manifests too.
"""

from __future__ import annotations

import csv
import difflib
import itertools
import os
import re
import tomllib
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ...core.errors import InputFileError
from ...core.scene.files import FORMATS, WRITERS
from ...core.transfer.config import TransferConfig, setting_type, user_settings
from ...core.transfer.presets import DEFAULT_PRESET, PRESETS, preset

PATHS = ("scene", "texture", "cameras")
"""The columns that name input files (relative to the manifest's folder)."""
COLUMNS = (*PATHS, "preset", "output")
BATCH_SETTINGS = ("threads",)
"""Settings the batch sets for every job (``--threads``), so that jobs sharing a machine do not fight."""
SETTINGS = tuple(name for name, _, _ in user_settings() if name not in BATCH_SETTINGS)
"""The settings a job may set: every user setting but the batch's own."""
OUTPUTS = tuple(ext for fmt in WRITERS for ext in FORMATS[fmt].extensions)
"""The result file endings the batch writes (the formats the tools write)."""
DEFAULT_OUTPUT = ".ply"
TRUE, FALSE = ("true", "yes", "on", "1"), ("false", "no", "off", "0")
NAME_CHARS = re.compile(r"[^A-Za-z0-9._+-]+")
NAME_MAX = 120


@dataclass(frozen=True)
class Job:
    """One transfer of a batch: its inputs, its settings as the manifest gives them, and its folder's name."""

    name: str
    """The job's folder in the batch's output folder; its result is ``name`` + the output's ending."""
    scene: Path
    texture: Path
    preset: str
    settings: dict[str, Any] = field(default_factory=dict)
    output: str = ""
    """The result's file name."""
    cameras: Path | None = None
    where: str = ""
    """Where the manifest gives it ("row 3", "[[product]] 1"), for messages."""

    def config(self, **machine: Any) -> TransferConfig:
        """The job's transfer settings, with the batch's machine settings (threads, device) on top."""
        return preset(self.preset, **{**self.settings, **machine})


def read_manifest(path: str | os.PathLike) -> list[Job]:
    """The jobs of a .csv or .toml manifest, checked; an error names the manifest and the row or table."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".csv", ".toml"):
        raise InputFileError(path, "a manifest is a .csv or a .toml file")
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError:
        raise InputFileError(path, "the manifest is not UTF-8 text") from None
    entries = _csv_entries(path, text) if suffix == ".csv" else _toml_entries(path, text)
    jobs = [_job(path, where, values) for where, values in entries]
    if not jobs:
        raise InputFileError(path, "the manifest lists no jobs")
    return _named(path, jobs)


def _csv_entries(path: Path, text: str) -> Iterator[tuple[str, dict[str, Any]]]:
    """(where, values) of each CSV row with a value; empty cells left out."""
    reader = csv.reader(text.splitlines())
    header = [cell.strip() for cell in next(reader, [])]
    missing = [c for c in ("scene", "texture") if c not in header]
    if missing:
        raise InputFileError(path, f"the header row lacks the column(s) {', '.join(missing)} (scene and texture)")
    doubled = sorted({c for c in header if header.count(c) > 1})
    if doubled:
        raise InputFileError(path, f"the header row names {', '.join(doubled)} twice")
    for column in header:
        _check_key(path, "the header row", column)
    for row in reader:
        where = f"row {reader.line_num}"
        if len(row) > len(header):
            raise InputFileError(path, f"{where}: {len(row)} cells under a header of {len(header)} columns")
        values = {k: v.strip() for k, v in zip(header, row) if v.strip()}
        if values:
            yield where, values


def _toml_entries(path: Path, text: str) -> Iterator[tuple[str, dict[str, Any]]]:
    """(where, values) of each TOML job: the ``[[job]]`` tables, then every combination of each ``[[product]]``."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputFileError(path, f"not valid TOML ({exc})") from None
    unknown = sorted(set(data) - {"preset", "settings", "job", "product"})
    if unknown:
        raise InputFileError(
            path, f"unknown key(s) {', '.join(unknown)}: a manifest holds preset, [settings], [[job]] and [[product]]"
        )
    common = {"preset": data["preset"]} if "preset" in data else {}
    common.update(_table(path, "[settings]", data.get("settings", {})))
    for key in common:
        _check_key(path, "[settings]", key)
    for n, table in enumerate(_tables(path, "job", data), 1):
        yield f"[[job]] {n}", {**common, **table}
    for n, table in enumerate(_tables(path, "product", data), 1):
        where = f"[[product]] {n}"
        lists = {k: v if isinstance(v, list) else [v] for k, v in table.items()}
        empty = [k for k, v in lists.items() if not v]
        if empty:
            raise InputFileError(path, f"{where}: the list {empty[0]} is empty")
        if "output" in table:
            raise InputFileError(path, f"{where}: a product names its outputs itself; give no output")
        for combination in itertools.product(*lists.values()):
            yield where, {**common, **dict(zip(lists, combination))}


def _tables(path: Path, key: str, data: dict) -> list[dict]:
    """The ``[[key]]`` tables of a TOML manifest."""
    tables = data.get(key, [])
    if not isinstance(tables, list) or not all(isinstance(t, dict) for t in tables):
        raise InputFileError(path, f"{key} must be written [[{key}]]: a table per entry")
    return tables


def _table(path: Path, where: str, value: Any) -> dict:
    if not isinstance(value, dict):
        raise InputFileError(path, f"{where} must be a table of setting = value")
    return value


def _check_key(path: Path, where: str, key: str) -> None:
    """Refuse a column or key that is no manifest column and no setting a job may set, suggesting the nearest."""
    if key in COLUMNS or key in SETTINGS:
        return
    if key in BATCH_SETTINGS:
        raise InputFileError(path, f"{where}: {key} is the batch's, for every job (--{key}), not a job's")
    near = difflib.get_close_matches(key, (*COLUMNS, *SETTINGS), n=1)
    hint = f"; did you mean {near[0]}?" if near else f"; a column is one of {', '.join(COLUMNS)} or a setting"
    raise InputFileError(path, f"{where}: unknown column or setting {key!r}{hint}")


def _job(path: Path, where: str, values: dict[str, Any]) -> Job:
    """One job from a row's or table's values, its settings typed and checked against the preset."""
    for key in values:
        _check_key(path, where, key)
    for key in ("scene", "texture"):
        if key not in values:
            raise InputFileError(path, f"{where}: no {key} given")
    files = {k: _input(path, where, k, values[k]) for k in PATHS if k in values}
    name = str(values.get("preset", DEFAULT_PRESET))
    if name not in PRESETS:
        raise InputFileError(path, f"{where}: unknown preset {name!r}; choose one of {', '.join(PRESETS)}")
    settings = {k: _typed(path, where, k, v) for k, v in values.items() if k in SETTINGS}
    try:
        preset(name, **settings)
    except ValueError as exc:
        raise InputFileError(path, f"{where}: {exc}") from None
    output = _output(path, where, values["output"]) if "output" in values else ""
    return Job("", files["scene"], files["texture"], name, settings, output, files.get("cameras"), where)


def _input(path: Path, where: str, key: str, value: Any) -> Path:
    """An input path, relative to the manifest's folder, made absolute (the workers may run elsewhere)."""
    if not isinstance(value, str) or not value:
        raise InputFileError(path, f"{where}: {key} must be a file name, got {value!r}")
    return Path(os.path.abspath(path.parent / Path(value).expanduser()))


def _output(path: Path, where: str, value: Any) -> str:
    """The result's file name: a bare name ending in a format the tools write."""
    text = str(value)
    if Path(text).name != text or text in (".", ".."):
        raise InputFileError(path, f"{where}: output {text!r} must be a file name, without a folder")
    if not text.lower().endswith(OUTPUTS) or _stem(text) == "":
        raise InputFileError(path, f"{where}: output {text!r} must end in one of {', '.join(OUTPUTS)}")
    return text


def _typed(path: Path, where: str, key: str, value: Any) -> Any:
    """A setting's value of its own type, from a CSV cell's text or a TOML value."""
    kind = setting_type(key)
    try:
        return _convert(kind, value)
    except (TypeError, ValueError):
        wanted = {bool: "true or false", int: "a whole number", float: "a number", tuple: "R,G,B in 0..1"}
        raise InputFileError(path, f"{where}: {key} must be {wanted.get(kind, 'text')}, got {value!r}") from None


def _convert(kind: type, value: Any) -> Any:
    """``value`` as a ``kind``; TypeError or ValueError when it is not one."""
    if kind is bool:
        if isinstance(value, bool):
            return value
        word = str(value).lower()
        if word not in (*TRUE, *FALSE):
            raise ValueError(value)
        return word in TRUE
    if isinstance(value, bool):
        raise TypeError(value)
    if kind is int:
        number = float(value) if isinstance(value, str) and "." in value else value
        if isinstance(number, float) and not number.is_integer():
            raise ValueError(value)
        return int(number)
    if kind is float:
        return float(value)
    if kind is tuple:
        parts = value.split(",") if isinstance(value, str) else value if isinstance(value, list) else [value]
        rgb = tuple(float(v) for v in parts)
        if len(rgb) not in (1, 3):
            raise ValueError(value)
        return rgb * 3 if len(rgb) == 1 else rgb
    if not isinstance(value, str):
        raise TypeError(value)
    return value


def _named(path: Path, jobs: list[Job]) -> list[Job]:
    """The jobs with their folder names: the output's name, else the scene's and texture's names and every
    setting that varies over the batch; two jobs with one name are an error naming both."""
    scenes, textures = _labels(j.scene for j in jobs), _labels(j.texture for j in jobs)
    cameras = _labels(j.cameras for j in jobs if j.cameras is not None)
    varying = _varying(jobs)
    named, seen = [], {}
    for job in jobs:
        if job.output:
            name = _stem(job.output)
        else:
            parts = [scenes[job.scene], textures[job.texture]]
            if "cameras" in varying and job.cameras is not None:
                parts.append(cameras[job.cameras])
            parts += [f"{k}{_shown(v)}" for k, v in _keyed(job) if k in varying and k != "cameras"]
            name = NAME_CHARS.sub("_", "-".join(parts))[:NAME_MAX]
        if name in seen:
            raise InputFileError(
                path,
                f"{seen[name]} and {job.where} are the same job or write the same folder {name!r}; remove one "
                "or give each an output name",
            )
        seen[name] = job.where
        output = job.output or name + DEFAULT_OUTPUT
        named.append(Job(name, job.scene, job.texture, job.preset, job.settings, output, job.cameras, job.where))
    return named


def _keyed(job: Job) -> list[tuple[str, Any]]:
    """What sets a job apart besides its scene and texture: its preset, cameras and settings."""
    return [("preset", job.preset), ("cameras", job.cameras), *sorted(job.settings.items())]


def _varying(jobs: list[Job]) -> set[str]:
    """The keys whose value is not the same for every job (a setting given for some jobs only varies)."""
    values: dict[str, set] = {}
    for job in jobs:
        for key, value in _keyed(job):
            values.setdefault(key, set()).add(repr(value))
    counts = {key: sum(1 for job in jobs if key in dict(_keyed(job))) for key in values}
    return {key for key, seen in values.items() if len(seen) > 1 or counts[key] < len(jobs)}


def _labels(paths: Iterable[Path]) -> dict[Path, str]:
    """Each distinct path's shortest name that tells it from the others: its stem, then with its folders."""
    distinct = list(dict.fromkeys(paths))
    for depth in range(1, max((len(p.parts) for p in distinct), default=1) + 1):
        labels = {p: "_".join([*p.parts[-depth:-1], _stem(p.name)]) for p in distinct}
        if len(set(labels.values())) == len(distinct):
            return labels
    return {p: str(p) for p in distinct}


def _stem(name: str) -> str:
    """A file name without its format's ending (``a.compressed.ply`` -> ``a``)."""
    lower = name.lower()
    ending = next((e for e in sorted(OUTPUTS, key=len, reverse=True) if lower.endswith(e)), Path(name).suffix)
    return name[: len(name) - len(ending)] if ending else name


def _shown(value: Any) -> str:
    """A setting's value in a folder name."""
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, tuple):
        return ",".join(f"{v:g}" for v in value)
    if isinstance(value, Path):
        return value.stem
    return str(value).lower() if isinstance(value, bool) else str(value)
