"""Views fitted to a scene when no cameras are given: a ring all round it, an arc on Blender's front, or an arc
where the capture's cameras stood, at the distance that frames it; or, for a capture seen from inside (a room), a
ring looking out from where its cameras stood."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from ..scene.gaussians import GaussianScene
from .axes import axis_vector, unit_vector
from .camera import Camera
from .cut import CUT_SAMPLE
from .poses import arc_views, orbit_views, outward_views
from .up import CONVENTION, front_for, scene_up
from .viewpoint import fitted_viewpoint

VIEW_KINDS = ("auto", "orbit", "arc", "front", "inside")
"""What :func:`auto_views` draws: inside where the splats say the cameras stood within the capture, else a ring
(auto); a ring all round; an arc on Blender's front; an arc where the cameras stood; a ring looking out."""
RING_FOV_DEG = 50.0
"""Views from a ring or an arc see this wide."""
INSIDE_PITCH_DEG = 10.0
"""Views from inside look this far down: a room's walls and the floor before them (a person holds a camera so)."""
INSIDE_FOV_DEG = 75.0
"""Views from inside see this wide (a phone's main camera): at 50° a room's upper walls, 1 m above the eye and 2 m
away, lie out of every view."""
LEVEL_DEG = 45.0
"""Front views keep the asked up unless the cameras looked within this angle of it (a capture lying flat: the
thinnest axis of a plant before its wall is the depth the cameras looked along)."""
STEEPEST_DEG = 60.0
"""The front arc stands at most this far above or below the middle (the arc turns about up; steeper, its views
crowd together)."""
FRONT_ARC_DEG = 30.0
"""The front arc's width: a capture seen from the front was walked along a short path."""
FRONT_CORE = 0.05
"""Front views frame the splats' middle between these quantiles across the look (5-95 %): a front capture's rim
holds large splats few cameras saw, far wider than any photo of it. Set on the fern's pictures against its own
cameras' (its only front capture): 2-98 % framed it from 1.9 times their distance, 10-90 % closer in than they
stood, 5-95 % about as they saw it."""


@dataclass(frozen=True)
class FrontArc:
    """Where front views stand: ``up``, the ``front`` they look from, its ``elevation_deg`` and the ``corners``
    (8, 3) of the splats' middle across the look, flat through the scene's middle, which the views frame."""

    up: np.ndarray
    front: np.ndarray
    elevation_deg: float
    corners: np.ndarray


def box_corners(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """The eight corners (8, 3) of the axis-aligned box from ``lo`` to ``hi``."""
    return np.array([[(lo, hi)[(i >> a) & 1][a] for a in range(3)] for i in range(8)])


def front_arc(scene: GaussianScene, up: Sequence[float], center: np.ndarray) -> FrontArc | None:
    """The arc on the side the capture's cameras stood (:func:`fitted_viewpoint`), None when the splats do not say
    (a capture seen all round): ``up`` unless the cameras looked within ``LEVEL_DEG`` of it, then the first of a
    trainer's -Y and Blender's +Z (then +X) across the look."""
    viewpoint = fitted_viewpoint(scene)
    if viewpoint is None or not viewpoint.telling:
        return None
    toward = viewpoint.direction
    up_v = unit_vector(up, "up")
    if abs(float(up_v @ toward)) > math.cos(math.radians(LEVEL_DEG)):
        across = [np.array(CONVENTION[axis]) for axis in (1, 2, 0)]
        up_v = next(a for a in across if abs(float(a @ toward)) <= math.cos(math.radians(LEVEL_DEG)))
    elevation = math.degrees(math.asin(max(-1.0, min(1.0, float(up_v @ toward)))))
    means = scene.means.detach().double().cpu().numpy()
    flat = means[:: math.ceil(len(means) / CUT_SAMPLE)] - center
    flat -= np.outer(flat @ toward, toward)
    lo, hi = np.quantile(flat, [FRONT_CORE, 1.0 - FRONT_CORE], axis=0)
    corners = box_corners(lo, hi)
    corners -= np.outer(corners @ toward, toward)
    steepest = max(-STEEPEST_DEG, min(STEEPEST_DEG, elevation))
    return FrontArc(up_v, toward, steepest, center + corners)


def auto_views(
    scene: GaussianScene,
    n: int,
    *,
    width: int = 256,
    height: int = 256,
    kind: str = "orbit",
    fov_deg: float | None = None,
    elevation_deg: float = 20.0,
    up: Sequence[float] | str = (0.0, 0.0, 1.0),
    quantile: float = 0.98,
    margin: float = 1.1,
) -> list[Camera]:
    """Ordered views fitted to a scene when no cameras are given.

    The Gaussians' robust bounds (``scene.bounds(quantile)``, ignoring floaters) give a box; the
    camera distance is the smallest at which all eight box corners project inside every image,
    times ``margin`` (1 = corners may touch the border). A box, not its bounding sphere, so flat or
    long objects fill the frame. ``fov_deg``: the views' horizontal field of view (None: ``RING_FOV_DEG``,
    from inside ``INSIDE_FOV_DEG``). ``kind``: "orbit" (a full ring), "arc" (a 60 degree
    forward-facing arc on the -y side, Blender's front), "front" (a 30 degree arc on the side the
    capture's cameras stood, :func:`front_arc`; "arc" where its splats do not say), "inside" (a ring
    looking out, ``INSIDE_PITCH_DEG`` down, from where a room's cameras stood, :func:`inside_point`; the first
    looks as the orbit's first does, the way Blender's Front view looks) or
    "auto" ("inside" where the splats say the cameras stood within the capture, else "orbit": a lone
    object has no known front). ``up`` is a vector (world +z, Blender's convention, by default),
    an axis name (:func:`axis_vector`) or "auto" for :func:`estimate_up_axis`.
    """
    if kind not in VIEW_KINDS:
        raise ValueError(f"kind must be one of {', '.join(VIEW_KINDS)}, got {kind!r}")
    if margin <= 0:
        raise ValueError(f"margin must be positive, got {margin}")
    if up == "auto":
        up = scene_up(scene, quantile)
    elif isinstance(up, str):
        up = axis_vector(up)
    kind = chosen_kind(scene, kind)
    if kind == "inside":
        fov_deg = INSIDE_FOV_DEG if fov_deg is None else fov_deg
        look = dict(
            width=width, height=height, fov_deg=fov_deg, pitch_deg=INSIDE_PITCH_DEG, up=up, first=-front_for(up)
        )
        return outward_views(inside_point(scene, quantile), n, **look)
    fov_deg = RING_FOV_DEG if fov_deg is None else fov_deg
    lo, hi = _framed_box(scene, quantile)
    center = (lo + hi) / 2.0
    sphere_radius = max(float(np.linalg.norm(hi - lo)) / 2.0, 1e-6)
    ring = dict(width=width, height=height, fov_deg=fov_deg, elevation_deg=elevation_deg, up=up, front=front_for(up))
    corners = box_corners(lo, hi)
    nearest = sphere_radius
    arc = front_arc(scene, up, center) if kind == "front" else None
    if arc is not None:
        ring.update(up=arc.up, front=arc.front, elevation_deg=arc.elevation_deg, arc_deg=FRONT_ARC_DEG)
        if float(np.ptp(arc.corners, axis=0).max()) / 2.0 >= _splat_reach(scene):
            corners, nearest = arc.corners, 0.0  # a front capture's middle may be framed from within its box
    fov_x = math.radians(fov_deg)
    fov_y = 2.0 * math.atan(math.tan(fov_x / 2.0) * height / width)
    make = arc_views if kind in ("arc", "front") else orbit_views

    def views(radius: float) -> list[Camera]:
        return make(center, radius, n, **ring)

    enclosing = sphere_radius / math.sin(min(fov_x, fov_y) / 2.0)  # the sphere fits: so does the box
    return views(_fitting_radius(views, corners, nearest, enclosing) * margin)


def chosen_kind(scene: GaussianScene, kind: str) -> str:
    """The views ``kind`` draws on ``scene``: "auto" is "inside" where the splats' sizes say the cameras stood
    within the capture (:attr:`Viewpoint.inside`), else "orbit"; any other kind is itself."""
    if kind != "auto":
        return kind
    viewpoint = fitted_viewpoint(scene)
    return "inside" if viewpoint is not None and viewpoint.inside else "orbit"


def inside_point(scene: GaussianScene, quantile: float = 0.98) -> np.ndarray:
    """Where views from inside stand: where the capture's cameras stood when its splats' sizes say they stood
    within it (:attr:`Viewpoint.inside`), else the middle of its robust bounds (a room asked to be seen from
    inside whose sizes do not tell)."""
    viewpoint = fitted_viewpoint(scene)
    if viewpoint is not None and viewpoint.inside:
        return np.array(viewpoint.point)
    lo, hi = (b.detach().double().cpu().numpy() for b in scene.bounds(quantile))
    return (lo + hi) / 2.0


FRAMED_SIGMAS = 3.0
"""A box the views frame reaches at least this many of a typical splat's largest sigma from its middle."""


def _framed_box(scene: GaussianScene, quantile: float) -> tuple[np.ndarray, np.ndarray]:
    """The box the views frame: the splats' robust bounds, or where those are smaller than a typical splat's own
    footprint (``FRAMED_SIGMAS`` x the median largest sigma) on every axis, a cube that reaches that far: one splat,
    or splats at one point, are framed instead of looked at from inside (a flat scene keeps its flat box)."""
    lo, hi = (b.detach().double().cpu().numpy() for b in scene.bounds(quantile))
    reach = _splat_reach(scene)
    if float((hi - lo).max()) / 2.0 >= reach:
        return lo, hi
    middle = (lo + hi) / 2.0
    return middle - reach, middle + reach


def _splat_reach(scene: GaussianScene) -> float:
    """``FRAMED_SIGMAS`` x a typical splat's largest sigma: the least half-size a framed box has."""
    return FRAMED_SIGMAS * float(scene.scales.detach().max(dim=1).values.median())


def _fitting_radius(views: Callable[[float], list[Camera]], corners: np.ndarray, low: float, high: float) -> float:
    """Smallest orbit radius in [low, high] at which every corner projects inside every view (bisection)."""

    def inside(radius: float) -> bool:
        for cam in views(radius):
            uv, depth = cam.project(corners)
            if np.any(depth <= 0) or np.any(uv < 0) or np.any(uv > [cam.width, cam.height]):
                return False
        return True

    for _ in range(30):
        mid = 0.5 * (low + high)
        low, high = (low, mid) if inside(mid) else (mid, high)
    return high
