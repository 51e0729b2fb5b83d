"""``cameras.json`` as the INRIA 3DGS trainer writes it: read into cameras and written back."""

from __future__ import annotations

import json
import math
import os
from collections.abc import Sequence
from typing import Any

import numpy as np

from ..atomic import atomic_write
from ..errors import CameraFileError
from .camera import Camera


# ---------------------------------------------------------------------------------------------------
# 3DGS cameras.json
# ---------------------------------------------------------------------------------------------------
def load_cameras_json(path: str | os.PathLike) -> list[Camera]:
    """Cameras from the ``cameras.json`` written by the INRIA 3DGS trainer.

    Entries: ``position`` = camera centre (world), ``rotation`` = camera->world 3x3 (OpenCV axes,
    rows as lists), ``fx, fy, width, height``; the principal point is the image centre unless the
    optional ``cx, cy`` keys (written by :func:`save_cameras_json` for off-centre cameras) exist.
    """
    try:
        with open(path, encoding="utf-8") as f:
            data = json.load(f)
    except (OSError, ValueError) as exc:
        raise CameraFileError(path, f"cannot read cameras.json: {exc}") from exc
    except RecursionError:
        raise CameraFileError(path, "cannot read cameras.json: its JSON is nested too deeply") from None
    if not isinstance(data, list) or not data:
        raise CameraFileError(path, "expected a non-empty JSON list of camera entries")
    return [_camera_from_json(path, i, entry) for i, entry in enumerate(data)]


def _camera_from_json(path: str | os.PathLike, index: int, entry: Any) -> Camera:
    """One cameras.json entry -> Camera; any problem becomes a CameraFileError naming the entry."""
    where = f"camera entry {index}"
    if not isinstance(entry, dict):
        raise CameraFileError(path, f"{where} is not a JSON object")
    missing = [k for k in ("width", "height", "position", "rotation", "fx", "fy") if k not in entry]
    if missing:
        raise CameraFileError(path, f"{where} lacks key(s) {', '.join(missing)}")
    width, height = _json_number(path, where, entry, "width"), _json_number(path, where, entry, "height")
    position = _json_array(path, where, entry, "position", (3,))
    rotation = _json_array(path, where, entry, "rotation", (3, 3))
    cx = _json_number(path, where, entry, "cx") if "cx" in entry else width / 2.0
    cy = _json_number(path, where, entry, "cy") if "cy" in entry else height / 2.0
    name = entry.get("img_name", entry.get("id", ""))
    try:
        return Camera.from_cam_to_world(
            rotation,
            position,
            _json_number(path, where, entry, "fx"),
            _json_number(path, where, entry, "fy"),
            cx,
            cy,
            width,
            height,
            str(name),
        )
    except ValueError as exc:
        raise CameraFileError(path, f"{where}: {exc}") from exc


def _json_number(path: str | os.PathLike, where: str, entry: dict, key: str) -> float:
    """A finite JSON number (not a bool or string) from ``entry[key]``."""
    value = entry[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(_as_float(value)):
        raise CameraFileError(path, f"{where}: {key} must be a finite number, got {_short(value)}")
    return value


def _as_float(value: float) -> float:
    """``value`` as a float; integers beyond the float range (JSON allows them) become Inf."""
    try:
        return float(value)
    except OverflowError:
        return math.inf


def _short(value: Any, limit: int = 60) -> str:
    """repr of a JSON value, cut to ``limit`` characters for a one-line message."""
    text = repr(value)
    return text if len(text) <= limit else text[:limit] + "..."


def _json_array(path: str | os.PathLike, where: str, entry: dict, key: str, shape: tuple[int, ...]) -> np.ndarray:
    """A finite float array of the given shape from nested JSON lists."""
    value = entry[key]
    try:
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        arr = None
    except OverflowError:  # an integer beyond the float range
        arr = None
    if arr is None or arr.shape != shape or _has_bool(value):
        raise CameraFileError(path, f"{where}: {key} must be numbers of shape {shape}, got {_short(value)}")
    if not np.all(np.isfinite(arr)):
        raise CameraFileError(path, f"{where}: {key} contains non-finite values")
    return arr


def _has_bool(value: Any) -> bool:
    """True if a nested JSON list holds a boolean (numpy would silently read it as 0/1)."""
    if isinstance(value, list):
        return any(_has_bool(v) for v in value)
    return isinstance(value, bool)


def save_cameras_json(path: str | os.PathLike, cameras: Sequence[Camera]) -> None:
    """Write cameras in the INRIA ``cameras.json`` layout, atomically (temp file + os.replace).

    ``cx, cy`` are added only for cameras whose principal point is off the image centre, so
    ordinary cameras produce exactly the trainer's layout and every camera round-trips.
    """
    if not cameras:
        raise ValueError("save_cameras_json needs at least one camera")
    entries = []
    for i, cam in enumerate(cameras):
        c2w = cam.cam_to_world
        entry: dict[str, Any] = {
            "id": i,
            "img_name": cam.name,
            "width": cam.width,
            "height": cam.height,
            "position": c2w[:3, 3].tolist(),
            "rotation": c2w[:3, :3].tolist(),
            "fy": cam.fy,
            "fx": cam.fx,
        }
        if cam.cx != cam.width / 2.0 or cam.cy != cam.height / 2.0:
            entry.update(cx=cam.cx, cy=cam.cy)
        entries.append(entry)
    _write_atomically(path, json.dumps(entries, indent=1))


def _write_atomically(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` atomically, reporting OS failures as a CameraFileError naming the file."""
    try:
        atomic_write(path, text)
    except OSError as exc:
        raise CameraFileError(path, f"cannot write: {exc.strerror or exc}") from exc
