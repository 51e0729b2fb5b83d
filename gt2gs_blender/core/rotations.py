"""Quaternion (w, x, y, z) -> rotation matrix in numpy, for INRIA's ``rot_0..3`` and COLMAP's ``qvec``
alike: one conversion for the COLMAP reader and the Blender edge (numpy only, no torch; the engine's
differentiable twin is ``scene.gaussians.quats_to_rotmats``)."""

from __future__ import annotations

from typing import Any

import numpy as np

DEGENERATE_NORM = 1e-12
"""Quaternions with a norm at or below this have no direction; they map to the identity rotation."""


def quats_to_matrices(quats: np.ndarray) -> np.ndarray:
    """(..., 4) quaternions of any norm to (..., 3, 3) float64 rotation matrices (zero -> identity)."""
    q = np.asarray(quats, np.float64)
    norm = np.linalg.norm(q, axis=-1, keepdims=True)
    ok = norm > DEGENERATE_NORM
    q = np.where(ok, q / np.where(ok, norm, 1.0), np.array([1.0, 0.0, 0.0, 0.0]))
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack(rotation_entries(w, x, y, z), axis=-1).reshape((*q.shape[:-1], 3, 3))


def rotation_entries(w: Any, x: Any, y: Any, z: Any) -> tuple[Any, ...]:
    """The nine entries, row by row, of the rotation of the unit quaternion (w, x, y, z): plain arithmetic, so
    numpy arrays, Python floats and the numba kernel (``render.numba_kernel``) share this one formula."""
    return (
        1 - 2 * (y * y + z * z),
        2 * (x * y - w * z),
        2 * (x * z + w * y),
        2 * (x * y + w * z),
        1 - 2 * (x * x + z * z),
        2 * (y * z - w * x),
        2 * (x * z - w * y),
        2 * (y * z + w * x),
        1 - 2 * (x * x + y * y),
    )
