"""World axes by name, and the snap of a direction to them: numpy only, so Blender's side (which may have no
torch) can read an object's up axis from its transform."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

SNAP_DEG = 25.0
"""An axis found within this angle of a world axis is that axis (captures keep a trainer's or Blender's convention;
a leaning neck or a sloping ground does not tilt the views)."""


def snapped(axis: np.ndarray) -> np.ndarray:
    """``axis`` (unit), or the world axis within ``SNAP_DEG`` of it (either sign: the sign is chosen later)."""
    world = int(np.argmax(np.abs(axis)))
    if abs(axis[world]) < math.cos(math.radians(SNAP_DEG)):
        return axis / np.linalg.norm(axis)
    unit = np.zeros(3)
    unit[world] = 1.0
    return unit


def axis_name(vector: Sequence[float]) -> str | None:
    """The signed world axis ``vector`` is ('+z', '-y', ...), or None when it is none of them."""
    v = np.asarray(vector, dtype=np.float64)
    world = int(np.argmax(np.abs(v)))
    if abs(v[world]) != 1.0 or np.count_nonzero(v) != 1:
        return None
    return ("+" if v[world] > 0 else "-") + "xyz"[world]


def up_from_rotation(rotation: Sequence[Sequence[float]]) -> str | None:
    """The object's own axis its ``rotation`` (3 x 3, world from object, scale allowed) turns to world +Z, named
    ('-y', ...), when within ``SNAP_DEG`` of one other than its own +Z: an artist who stood a capture upright in
    Blender said which way is up. None for an object left on its own +Z, however tilted (the splats decide), or
    turned off every axis."""
    r = np.asarray(rotation, dtype=np.float64)
    local = np.linalg.solve(r / np.linalg.norm(r, axis=0, keepdims=True), [0.0, 0.0, 1.0])
    near = snapped(local / np.linalg.norm(local))
    name = axis_name(near * np.sign(local @ near))
    return None if name == "+z" else name


def axis_vector(name: str) -> tuple[float, float, float]:
    """The unit vector of an axis named by an optional sign and x, y or z ('+z', '-y', 'x')."""
    sign, letter = (name[0], name[1:]) if name[:1] in "+-" else ("+", name)
    if letter not in ("x", "y", "z"):
        raise ValueError(f"up must be a 3-vector, 'auto' or an axis such as +z or -y, got {name!r}")
    vector = [0.0, 0.0, 0.0]
    vector["xyz".index(letter)] = -1.0 if sign == "-" else 1.0
    return (vector[0], vector[1], vector[2])


def unit_vector(v: Sequence[float], what: str) -> np.ndarray:
    """``v`` normalised; ValueError if it is zero or not finite."""
    arr = np.asarray(v, dtype=np.float64)
    norm = np.linalg.norm(arr)
    if arr.shape != (3,) or not math.isfinite(norm) or norm < 1e-12:
        raise ValueError(f"{what} must be a finite non-zero 3-vector, got {arr.tolist()}")
    return arr / norm
