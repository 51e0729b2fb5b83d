"""Camera poses: a look-at camera, rings and arcs of views about a point, smooth paths through views.

GT^2 visits views in order and warps matches from one view to the next, so the rings and arcs come ordered along
their path (consecutive views are neighbours)."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from .axes import unit_vector
from .camera import Camera


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
    forward = unit_vector(target_v - eye_v, "look direction")
    right = np.cross(forward, unit_vector(up, "up"))
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


def outward_views(
    eye: Sequence[float],
    n: int,
    *,
    width: int,
    height: int,
    fov_deg: float = 50.0,
    pitch_deg: float = 10.0,
    up: Sequence[float] = (0.0, 0.0, 1.0),
    first: Sequence[float] = (0.0, 1.0, 0.0),
) -> list[Camera]:
    """``n`` cameras standing at ``eye`` and looking out all round it, ``pitch_deg`` below the plane normal to
    ``up``, ordered by azimuth: the first looks along ``first`` (as Blender's Front view does, by default), each
    next one counter-clockwise seen from ``up`` (views from inside a room)."""
    if not -90.0 < pitch_deg < 90.0:
        raise ValueError(f"pitch_deg must be in (-90, 90), got {pitch_deg}")
    up_v, looks = _directions(np.linspace(0.0, 360.0, max(n, 0), endpoint=False), -pitch_deg, up, first)
    at = np.asarray(eye, dtype=np.float64)
    return [
        look_at(at, at + look, width=width, height=height, fov_deg=fov_deg, up=up_v, name=f"inside_{i:03d}")
        for i, look in enumerate(looks)
    ]


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
    if not (math.isfinite(radius) and radius > 0):
        raise ValueError(f"radius must be positive, got {radius}")
    if not -90.0 < elevation_deg < 90.0:
        raise ValueError(f"elevation_deg must be in (-90, 90), got {elevation_deg}")
    up_v, offsets = _directions(azimuths_deg, elevation_deg, up, front)
    c = np.asarray(center, dtype=np.float64)
    return [
        look_at(c + radius * offset, c, width=width, height=height, fov_deg=fov_deg, up=up_v, name=f"{prefix}_{i:03d}")
        for i, offset in enumerate(offsets)
    ]


def _directions(
    azimuths_deg: np.ndarray, elevation_deg: float, up: Sequence[float], front: Sequence[float]
) -> tuple[np.ndarray, np.ndarray]:
    """Unit ``up`` and the unit directions (n, 3) at ``azimuths_deg`` (0 = ``front``, counter-clockwise seen from
    ``up``), ``elevation_deg`` above the plane normal to ``up``."""
    if len(azimuths_deg) < 1:
        raise ValueError("at least one view is needed")
    up_v = unit_vector(up, "up")
    e1 = _horizontal_direction(front, up_v)
    e2 = np.cross(up_v, e1)
    el = math.radians(elevation_deg)
    rows = [
        math.cos(el) * (math.cos(az) * e1 + math.sin(az) * e2) + math.sin(el) * up_v for az in np.radians(azimuths_deg)
    ]
    return up_v, np.array(rows)


def _horizontal_direction(front: Sequence[float], up: np.ndarray) -> np.ndarray:
    """``front`` projected onto the plane normal to ``up``; if they are parallel, the world axis
    least aligned with ``up`` (never parallel to it) projected instead."""
    direction = np.asarray(front, dtype=np.float64)
    flat = direction - (direction @ up) * up
    if np.linalg.norm(flat) < 1e-6:
        axis = np.eye(3)[np.argmin(np.abs(up))]
        flat = axis - (axis @ up) * up
    return flat / np.linalg.norm(flat)
