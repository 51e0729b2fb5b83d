"""A scene's up axis from its splats (what it stands on, how it lies) and the ring's front for that up."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..scene.gaussians import GaussianScene
from .axes import snapped, unit_vector

FLATNESS = 0.5
"""Else a scene is flat (a ground patch, a tabletop object, a donut) when its smallest principal variance is below
this share of the middle one: up is that axis."""
ELONGATION = 3.0
"""A scene stands tall (a guitar on its stand, a lamp) when its largest variance is this many times the middle one
and one end of it is a support (:func:`_support_sign`): up is that axis, before any flatness (a guitar is flat too)."""
SUPPORT_SLAB = 0.15
SUPPORT_RATIO = 1.5
"""The sign: the end whose outer ``SUPPORT_SLAB`` of the height spreads this many times wider than the other's is the
bottom (a stand's feet, the ground under a robot); else the convention."""
SUPPORT_MASS = 0.25
"""... and holds at least this share of the other end's splat centres: what a scene stands on is where its splats lie
(a garden's sparse ring of tree tops spreads wider than its lawn: 2,373 centres against 78,822)."""
CONVENTION = {0: (1.0, 0.0, 0.0), 1: (0.0, -1.0, 0.0), 2: (0.0, 0.0, 1.0)}
"""Each world axis's up when the splats do not say: +X, a trainer's -Y (its cameras' y points down), Blender's +Z."""


def estimate_up_axis(points: np.ndarray, prefer: Sequence[float] | None = None) -> np.ndarray:
    """The scene's up axis from its splat centres: the longest principal axis of a tall scene that stands on one end,
    else the thinnest of a flat one, else the world axis nearest ``prefer`` (by default +Z); snapped to a world axis
    within ``SNAP_DEG``, pointing away from the end the scene stands on (:func:`_support_sign`), else along
    ``prefer`` or the axis's ``CONVENTION``."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    default = np.array(CONVENTION[2]) if prefer is None else unit_vector(prefer, "prefer")
    if len(pts) < 4:
        return default
    variances, axes = np.linalg.eigh(np.cov(pts.T))
    if variances[2] > ELONGATION * variances[1]:
        tall = snapped(axes[:, 2])
        if (sign := _support_sign(pts, pts @ tall, tall)) != 0:
            return sign * tall
    axis = snapped(axes[:, 0] if variances[0] < FLATNESS * variances[1] else default)
    if (sign := _support_sign(pts, pts @ axis, axis)) != 0:
        return sign * axis
    world = int(np.argmax(np.abs(axis)))
    reference = np.asarray(CONVENTION[world]) if prefer is None and abs(axis[world]) == 1.0 else default
    return axis if axis @ reference >= 0 else -axis


def _support_sign(points: np.ndarray, heights: np.ndarray, axis: np.ndarray) -> int:
    """+1 when the scene stands on the low end of ``axis`` (its outer slab of heights spreads ``SUPPORT_RATIO``
    times wider across than the high end's and holds ``SUPPORT_MASS`` of its centres), -1 for the high end, 0 when
    neither stands out."""
    lo, hi = np.quantile(heights, [0.01, 0.99])
    if not hi > lo:
        return 0
    across = points - np.outer(heights, axis)

    def spread(slab: np.ndarray) -> float:
        if slab.sum() < 4:
            return 0.0
        return float(np.sqrt(max(np.linalg.eigvalsh(np.cov(across[slab].T))[-2:].prod(), 0.0)))

    slab = SUPPORT_SLAB * (hi - lo)
    bottom, top = (heights >= lo) & (heights <= lo + slab), (heights <= hi) & (heights >= hi - slab)
    low, high = spread(bottom), spread(top)
    if low > SUPPORT_RATIO * high and bottom.sum() >= SUPPORT_MASS * top.sum():
        return 1
    if high > SUPPORT_RATIO * low and top.sum() >= SUPPORT_MASS * bottom.sum():
        return -1
    return 0


def front_for(up: Sequence[float]) -> np.ndarray:
    """The ring's first direction for ``up``: Blender's front (-Y) carried by the turn that takes +Z to a world-axis
    ``up`` (a half turn about X for -Z, a quarter turn about X for +-Y, about Y for +-X), so a capture and its copy
    turned to another up get the same views; -Y for an up off the world axes."""
    u = unit_vector(up, "up")
    world = int(np.argmax(np.abs(u)))
    sign = float(np.sign(u[world]))
    if abs(u[world]) != 1.0 or world == 0:
        return np.array([0.0, -1.0, 0.0])
    return np.array([0.0, -sign, 0.0]) if world == 2 else np.array([0.0, 0.0, sign])


def scene_up(scene: GaussianScene, quantile: float = 0.98) -> np.ndarray:
    """:func:`estimate_up_axis` of the splat centres inside the scene's robust bounds (floaters left out)."""
    lo, hi = (b.detach().double().cpu().numpy() for b in scene.bounds(quantile))
    means = scene.means.detach().double().cpu().numpy()
    return estimate_up_axis(means[np.all((means >= lo) & (means <= hi), axis=1)])
