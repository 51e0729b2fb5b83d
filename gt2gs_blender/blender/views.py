"""Blender cameras as 3DGS ``cameras.json`` entries in a splat object's own (PLY) space, and back.

Blender cameras look down -z with y up; ``core`` uses OpenCV axes, so the camera-to-world rotation is ``R_cv
= R_blender @ diag(1, -1, -1)`` (docs/architecture.md, "Conventions"). The PLY lives in the object's local
space, so each camera is expressed relative to the object: ``inverse(object.matrix_world) @
camera.matrix_world``, with the scale taken out of the rotation (exact for uniform object scale; a
non-uniform scale makes the views approximate). Intrinsics follow Blender's sensor fit, lens shift and the
scene's render resolution. ``add_camera`` makes the Blender camera that sees what a ``core`` camera sees
(the display's fidelity test and bench render the project's own views with it).
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Iterable
from functools import lru_cache
from typing import Any

import numpy as np

from ..core.cameras.spread import seen_from_front
from ..core.transfer.config import FORWARD_SPREAD_DEG

BLENDER_TO_CV = np.diag([1.0, -1.0, -1.0])
SENSOR_WIDTH_MM = 36.0
"""The sensor width ``add_camera`` gives its cameras (Blender's default), fitted horizontally."""


class ViewError(ValueError):
    """Cameras cannot be used as views; the message is meant for the user."""


def render_size(scene) -> tuple[int, int]:
    """The scene's output size in pixels (resolution times percentage)."""
    render = scene.render
    scale = render.resolution_percentage / 100.0
    return max(1, round(render.resolution_x * scale)), max(1, round(render.resolution_y * scale))


def intrinsics(
    lens: float,
    sensor_width: float,
    sensor_height: float,
    sensor_fit: str,
    shift_x: float,
    shift_y: float,
    width: int,
    height: int,
) -> tuple[float, float, float, float]:
    """(fx, fy, cx, cy) in pixels for a Blender perspective camera (square pixels)."""
    if sensor_fit == "HORIZONTAL" or (sensor_fit == "AUTO" and width >= height):
        focal = lens / sensor_width * width
    else:  # VERTICAL spans the height with sensor_height; AUTO spans the larger side with sensor_width
        focal = lens / (sensor_height if sensor_fit == "VERTICAL" else sensor_width) * height
    larger = max(width, height)
    return focal, focal, width / 2.0 - shift_x * larger, height / 2.0 + shift_y * larger


def camera_pose(camera_to_world: np.ndarray, object_to_world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(position, OpenCV camera-to-world rotation) of a Blender camera in an object's local space."""
    local = np.linalg.inv(np.asarray(object_to_world, np.float64)) @ np.asarray(camera_to_world, np.float64)
    linear = local[:3, :3]
    norms = np.linalg.norm(linear, axis=0)
    if np.any(norms < 1e-12) or not np.all(np.isfinite(local)):
        raise ViewError("a camera or the object has a degenerate (zero or non-finite) transform")
    u, _, vt = np.linalg.svd(linear / norms)
    rotation = u @ vt
    if np.linalg.det(rotation) < 0:
        raise ViewError("a camera or the object is mirrored (negative scale); views cannot be built")
    return local[:3, 3], rotation @ BLENDER_TO_CV


def camera_entries(cameras: Iterable[Any], scene, object_to_world: np.ndarray) -> list[dict[str, Any]]:
    """``cameras.json`` entries for perspective camera objects, in the given order."""
    width, height = render_size(scene)
    entries = []
    for obj in cameras:
        data = obj.data
        if data.type != "PERSP":
            raise ViewError(f"camera {obj.name!r} is {data.type.lower()}; only perspective cameras can be views")
        position, rotation = camera_pose(np.array(obj.matrix_world), object_to_world)
        fx, fy, cx, cy = intrinsics(
            data.lens, data.sensor_width, data.sensor_height, data.sensor_fit, data.shift_x, data.shift_y, width, height
        )
        if not all(math.isfinite(v) and v > 0 for v in (fx, fy)):
            raise ViewError(f"camera {obj.name!r} has an unusable focal length")
        entries.append(
            {
                "id": len(entries),
                "img_name": obj.name,
                "width": width,
                "height": height,
                "position": position.tolist(),
                "rotation": rotation.tolist(),
                "fx": fx,
                "fy": fy,
                "cx": cx,
                "cy": cy,
            }
        )
    if not entries:
        raise ViewError("no cameras to use as views")
    return entries


def camera_matrix(world_to_cam: np.ndarray) -> np.ndarray:
    """The Blender ``matrix_world`` (4 x 4) of a camera whose OpenCV world-to-camera transform is ``world_to_cam``."""
    cam_to_world = np.linalg.inv(np.asarray(world_to_cam, np.float64))
    matrix = np.eye(4)
    matrix[:3, :3] = cam_to_world[:3, :3] @ BLENDER_TO_CV
    matrix[:3, 3] = cam_to_world[:3, 3]
    return matrix


def add_camera(view: Any, collection: Any, name: str | None = None) -> Any:
    """A new Blender camera object in ``collection`` that sees what ``view`` (a ``core`` camera: square pixels,
    centred principal point) sees when the scene renders at the view's size."""
    import bpy
    import mathutils

    data = bpy.data.cameras.new(name or view.name or "view")
    data.sensor_fit, data.sensor_width = "HORIZONTAL", SENSOR_WIDTH_MM
    data.lens = view.fx / view.width * SENSOR_WIDTH_MM
    obj = bpy.data.objects.new(data.name, data)
    obj.matrix_world = mathutils.Matrix(camera_matrix(view.world_to_cam).tolist())
    collection.objects.link(obj)
    return obj


def views_from_front(settings, scene) -> bool | None:
    """Whether the views a run will take (``settings.view_source``) all look at the scene from one side, what
    the automatic Projection and Texture Moves Splats follow; None while there are no views to tell."""
    if settings.view_source == "AUTO":  # the ring surrounds the object; one view alone or the front arc do not
        return settings.n_views == 1 or settings.view_kind == "front"
    if settings.view_source == "CAMERAS_JSON":
        import bpy

        path = os.path.abspath(bpy.path.abspath(settings.cameras_json))  # "//" is the .blend's folder
        return _file_from_front(path, _mtime(path))
    collection = settings.camera_collection if settings.view_source == "COLLECTION" else None
    if settings.view_source == "COLLECTION" and collection is None:
        return None
    objects = collection.all_objects if collection is not None else scene.objects
    forwards = [-np.array(o.matrix_world)[:3, 2] for o in objects if o.type == "CAMERA"]  # Blender looks down -z
    return seen_from_front(np.array(forwards), FORWARD_SPREAD_DEG) if forwards else None


def _mtime(path: str) -> float | None:
    try:
        return os.path.getmtime(path)
    except OSError:
        return None


@lru_cache(maxsize=4)
def _file_from_front(path: str, mtime: float | None) -> bool | None:
    """:func:`views_from_front` for a cameras.json (read once per change; None when it cannot be read)."""
    if mtime is None:
        return None
    try:
        with open(path, encoding="utf-8") as f:
            entries = json.load(f)
        forwards = np.array([np.asarray(e["rotation"], np.float64)[:, 2] for e in entries])  # OpenCV: +z looks
    except (OSError, ValueError, TypeError, KeyError, IndexError):
        return None
    return seen_from_front(forwards, FORWARD_SPREAD_DEG) if len(forwards) and np.isfinite(forwards).all() else None
