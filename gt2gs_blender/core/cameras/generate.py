"""Generated views: rings and arcs fitted around a scene, look-at poses and smooth camera paths.

GT^2 visits views in order and warps matches from one view to the next, so the generators return
views ordered along their path (consecutive views are neighbours)."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from ..scene.gaussians import GaussianScene
from .axes import axis_vector, snapped
from .camera import Camera
from .viewpoint import fitted_viewpoint


# ---------------------------------------------------------------------------------------------------
# Generated views
# ---------------------------------------------------------------------------------------------------
def look_at(
    eye: Sequence[float],
    target: Sequence[float],
    *,
    width: int,
    height: int,
    fov_deg: float = 50.0,
    up: Sequence[float] = (0.0, 0.0, 1.0),
    name: str = "",
) -> Camera:
    """A camera at ``eye`` looking at ``target`` with ``up`` pointing up in the image.

    ``fov_deg`` is the horizontal field of view; pixels are square and the principal point centred.
    """
    if not 0.0 < fov_deg < 180.0:
        raise ValueError(f"fov_deg must be in (0, 180), got {fov_deg}")
    eye_v, target_v = np.asarray(eye, dtype=np.float64), np.asarray(target, dtype=np.float64)
    forward = _unit(target_v - eye_v, "look direction")
    right = np.cross(forward, _unit(up, "up"))
    if np.linalg.norm(right) < 1e-6:
        raise ValueError("look_at: the view direction is parallel to the up vector")
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    f = (width / 2.0) / math.tan(math.radians(fov_deg) / 2.0)
    return Camera.from_cam_to_world(
        np.stack([right, down, forward], axis=1), eye_v, f, f, width / 2.0, height / 2.0, width, height, name
    )


def camera_path(cameras: Sequence[Camera], frames_per_gap: int, *, closed: bool = False) -> list[Camera]:
    """A smooth path through ``cameras`` in their order, as a rendered video would go: ``frames_per_gap``
    frames from each camera to the next (the camera itself first), rotation by slerp, centre linear,
    intrinsics and size of the gap's first camera; ``closed`` adds the gap from the last back to the first,
    else the last camera ends the path. Consecutive cameras must turn by less than 180 degrees."""
    if frames_per_gap < 1 or not cameras:
        raise ValueError(f"need cameras and frames_per_gap >= 1, got {len(cameras)} and {frames_per_gap}")
    gaps = len(cameras) if closed and len(cameras) > 1 else len(cameras) - 1
    path = []
    for i in range(gaps):
        a, b = cameras[i], cameras[(i + 1) % len(cameras)]
        r_a = a.cam_to_world[:3, :3]
        axis_angle = _rotation_log(r_a.T @ b.cam_to_world[:3, :3])
        for k in range(frames_per_gap):
            t = k / frames_per_gap
            path.append(
                Camera.from_cam_to_world(
                    r_a @ _rotation_exp(t * axis_angle),
                    (1 - t) * a.center + t * b.center,
                    a.fx,
                    a.fy,
                    a.cx,
                    a.cy,
                    a.width,
                    a.height,
                    f"{a.name}+{k}",
                )
            )
    return path if closed and len(cameras) > 1 else [*path, cameras[-1]]


def _rotation_log(r: np.ndarray) -> np.ndarray:
    """Axis times angle (radians) of a rotation matrix with angle below 180 degrees."""
    angle = math.acos(min(1.0, max(-1.0, (np.trace(r) - 1.0) / 2.0)))
    if angle > math.pi - 1e-6:
        raise ValueError("consecutive cameras turn by 180 degrees: the path between them is ambiguous")
    skew = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]]) / 2.0
    return skew if angle < 1e-12 else skew * angle / math.sin(angle)


def _rotation_exp(w: np.ndarray) -> np.ndarray:
    """Rotation matrix of axis times angle ``w`` (Rodrigues)."""
    angle = float(np.linalg.norm(w))
    k = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    if angle < 1e-12:
        return np.eye(3) + k
    k /= angle
    return np.eye(3) + math.sin(angle) * k + (1.0 - math.cos(angle)) * (k @ k)


def orbit_views(
    center: Sequence[float],
    radius: float,
    n: int,
    *,
    width: int,
    height: int,
    fov_deg: float = 50.0,
    elevation_deg: float = 20.0,
    up: Sequence[float] = (0.0, 0.0, 1.0),
    front: Sequence[float] = (0.0, -1.0, 0.0),
) -> list[Camera]:
    """``n`` cameras on a ring around ``center`` looking at it, ordered by azimuth.

    The ring lies ``elevation_deg`` above the plane normal to ``up``; the first camera sits on the
    ``front`` side (Blender's front view by default: on -y, looking along +y) and azimuth increases
    counter-clockwise seen from ``up``.
    """
    azimuths = np.linspace(0.0, 360.0, n, endpoint=False)
    return _ring_views(center, radius, azimuths, elevation_deg, up, front, width, height, fov_deg, "orbit")


def arc_views(
    center: Sequence[float],
    radius: float,
    n: int,
    *,
    width: int,
    height: int,
    fov_deg: float = 50.0,
    arc_deg: float = 60.0,
    elevation_deg: float = 10.0,
    up: Sequence[float] = (0.0, 0.0, 1.0),
    front: Sequence[float] = (0.0, -1.0, 0.0),
) -> list[Camera]:
    """``n`` cameras on an arc of ``arc_deg`` degrees on the ``front`` side of ``center``, looking at
    it and ordered along the arc: forward-facing views for front-facing scenes (like LLFF)."""
    if not 0.0 <= arc_deg < 360.0:
        raise ValueError(f"arc_deg must be in [0, 360), got {arc_deg}")
    azimuths = np.linspace(-arc_deg / 2.0, arc_deg / 2.0, n) if n > 1 else np.zeros(n)
    return _ring_views(center, radius, azimuths, elevation_deg, up, front, width, height, fov_deg, "arc")


def _ring_views(
    center: Sequence[float],
    radius: float,
    azimuths_deg: np.ndarray,
    elevation_deg: float,
    up: Sequence[float],
    front: Sequence[float],
    width: int,
    height: int,
    fov_deg: float,
    prefix: str,
) -> list[Camera]:
    """Cameras at the given azimuths (0 = ``front``) and elevation on a sphere around ``center``."""
    if len(azimuths_deg) < 1:
        raise ValueError("at least one view is needed")
    if not (math.isfinite(radius) and radius > 0):
        raise ValueError(f"radius must be positive, got {radius}")
    if not -90.0 < elevation_deg < 90.0:
        raise ValueError(f"elevation_deg must be in (-90, 90), got {elevation_deg}")
    up_v = _unit(up, "up")
    e1 = _horizontal_direction(front, up_v)
    e2 = np.cross(up_v, e1)
    c = np.asarray(center, dtype=np.float64)
    el = math.radians(elevation_deg)
    cameras = []
    for i, az in enumerate(np.radians(azimuths_deg)):
        offset = math.cos(el) * (math.cos(az) * e1 + math.sin(az) * e2) + math.sin(el) * up_v
        cameras.append(
            look_at(
                c + radius * offset, c, width=width, height=height, fov_deg=fov_deg, up=up_v, name=f"{prefix}_{i:03d}"
            )
        )
    return cameras


def _horizontal_direction(front: Sequence[float], up: np.ndarray) -> np.ndarray:
    """``front`` projected onto the plane normal to ``up``; if they are parallel, the world axis
    least aligned with ``up`` (never parallel to it) projected instead."""
    direction = np.asarray(front, dtype=np.float64)
    flat = direction - (direction @ up) * up
    if np.linalg.norm(flat) < 1e-6:
        axis = np.eye(3)[np.argmin(np.abs(up))]
        flat = axis - (axis @ up) * up
    return flat / np.linalg.norm(flat)


def _unit(v: Sequence[float], what: str) -> np.ndarray:
    """``v`` normalised; ValueError if it is zero or not finite."""
    arr = np.asarray(v, dtype=np.float64)
    norm = np.linalg.norm(arr)
    if arr.shape != (3,) or not math.isfinite(norm) or norm < 1e-12:
        raise ValueError(f"{what} must be a finite non-zero 3-vector, got {arr.tolist()}")
    return arr / norm


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
    default = np.array(CONVENTION[2]) if prefer is None else _unit(prefer, "prefer")
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
    u = _unit(up, "up")
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


VIEW_KINDS = ("auto", "orbit", "arc", "front")
"""What :func:`auto_views` draws: a ring all round, an arc on Blender's front, an arc where the cameras stood."""
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
    up_v = _unit(up, "up")
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
    kind: str = "auto",
    fov_deg: float = 50.0,
    elevation_deg: float = 20.0,
    up: Sequence[float] | str = (0.0, 0.0, 1.0),
    quantile: float = 0.98,
    margin: float = 1.1,
) -> list[Camera]:
    """Ordered views fitted to a scene when no cameras are given.

    The Gaussians' robust bounds (``scene.bounds(quantile)``, ignoring floaters) give a box; the
    camera distance is the smallest at which all eight box corners project inside every image,
    times ``margin`` (1 = corners may touch the border). A box, not its bounding sphere, so flat or
    long objects fill the frame. ``kind``: "orbit" (a full ring), "arc" (a 60 degree
    forward-facing arc on the -y side, Blender's front), "front" (a 30 degree arc on the side the
    capture's cameras stood, :func:`front_arc`; "arc" where its splats do not say) or "auto" (= orbit:
    a lone object has no known front). ``up`` is a vector (world +z, Blender's convention, by default),
    an axis name (:func:`axis_vector`) or "auto" for :func:`estimate_up_axis`.
    """
    if kind not in VIEW_KINDS:
        raise ValueError(f"kind must be one of {', '.join(VIEW_KINDS)}, got {kind!r}")
    if margin <= 0:
        raise ValueError(f"margin must be positive, got {margin}")
    lo, hi = _framed_box(scene, quantile)
    center = (lo + hi) / 2.0
    sphere_radius = max(float(np.linalg.norm(hi - lo)) / 2.0, 1e-6)
    if up == "auto":
        up = scene_up(scene, quantile)
    elif isinstance(up, str):
        up = axis_vector(up)
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


CUT_SHARE = 0.999
"""A view cut to its object keeps this share of the splat centres in front of it inside, along each axis: a few
floaters do not decide its size."""
CUT_SAMPLE = 65536
"""The cut reads at most this many of the centres, evenly strided: the share needs no more (a 500,000-splat capture
took 0.5 s to project whole for 16 views)."""
CUT_MARGIN = 1.1
CUT_PAD = 8
"""It keeps their extent times this margin and this many pixels a side more: the outermost splats' own footprints."""
CUT_STEP = 8
"""Views are cut by this many pixels a side at a time: a size of whole 8 px rasterizer tiles, and of whole tiles at
half size (Feature Scale 0.5), stays so, and the pixel grid stays where it was."""


def cut_to_points(
    cameras: Sequence[Camera], points: np.ndarray, margin: float = CUT_MARGIN, pad: int = CUT_PAD
) -> list[Camera]:
    """Views of one size cut about their centres to the part of their images that ``points`` (world, (N, 3)) fill
    in any of them (``CUT_SHARE`` of the points in front along each axis), with ``margin`` and ``pad``, never grown
    and cut by ``CUT_STEP`` a side: a tall guitar framed in square views leaves half of each empty."""
    if not cameras or len(points) == 0:
        return list(cameras)
    points = points[:: math.ceil(len(points) / CUT_SAMPLE)]
    size = np.array([cameras[0].width, cameras[0].height])
    if any((cam.width, cam.height) != tuple(size) for cam in cameras):
        raise ValueError("cut_to_points needs views of one size")
    reach = np.zeros(2)
    for cam in cameras:
        uv, depth = cam.project(points)
        if not np.any(depth > 0):
            return list(cameras)
        reach = np.maximum(reach, np.quantile(np.abs(uv[depth > 0] - [cam.cx, cam.cy]), CUT_SHARE, axis=0))
    wanted = 2.0 * (reach * margin + pad)
    width, height = (size - 2 * CUT_STEP * np.floor(np.maximum(size - wanted, 0.0) / (2 * CUT_STEP))).astype(int)
    return [cam.cropped(int(width), int(height)) for cam in cameras]


def cut_to_scene(cameras: Sequence[Camera], scene: GaussianScene) -> list[Camera]:
    """:func:`cut_to_points` of the scene's splat centres."""
    return cut_to_points(cameras, scene.means.detach().double().cpu().numpy())


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
