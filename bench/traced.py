"""Synthetic captures made the way a capture is: textured boxes ray-traced exactly from posed cameras, written as
an LLFF capture and fitted by the project's own ``fit`` (3DGS from random points), so the splats' sizes are a
trainer's, not made up. ``bench/room.py`` and ``bench/viewpoints.py`` build their scenes from these."""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from recognise_scenes import CACHE, SHARED

from gt2gs_blender.app.images import write_png
from gt2gs_blender.core.cameras.camera import Camera
from gt2gs_blender.core.fit.trainer import FitConfig, fit_llff
from gt2gs_blender.core.transfer.texture import load_texture

TEXTURES = SHARED / "data" / "textures"


@dataclass(frozen=True)
class Face:
    """A box face's look: its texture's file name in the shared textures (None: plaster), one repeat's size in
    metres, and a shade it is multiplied by (faces lit unlike one another, as a room's are)."""

    texture: str | None
    size: float
    shade: float


@dataclass(frozen=True)
class Box:
    """An axis-aligned box from ``lo`` to ``hi`` (metres); ``faces`` by (axis, 0 low / 1 high). A ``shell`` is seen
    from inside (a room's walls, the rays leaving it), any other box from outside (a cabinet, an object)."""

    lo: tuple[float, float, float]
    hi: tuple[float, float, float]
    faces: dict[tuple[int, int], Face] = field(hash=False)
    shell: bool = False


def one_look(texture: str | None, size: float, shades: tuple[float, float, float]) -> dict[tuple[int, int], Face]:
    """Faces all of one texture and size, shaded by axis (both faces of an axis alike)."""
    return {(axis, high): Face(texture, size, shades[axis]) for axis in range(3) for high in (0, 1)}


def trace(
    cam: Camera, boxes: list[Box], width: int, height: int, background: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """``boxes`` from ``cam`` at ``width`` x ``height``: colour (H, W, 3) in [0, 1] (``background`` where a ray
    hits nothing) and depth along the rays (inf there)."""
    small = cam.scaled(width / cam.width)
    u, v = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
    rays = np.stack([(u - small.cx) / small.fx, (v - small.cy) / small.fy, np.ones_like(u)], -1)
    dirs = rays @ small.cam_to_world[:3, :3].T
    dirs /= np.linalg.norm(dirs, axis=-1, keepdims=True)
    origin = small.center
    depth = np.full((height, width), np.inf)
    hit = np.full((height, width), -1)
    hit_axis = np.zeros((height, width), dtype=int)
    for index, box in enumerate(boxes):
        t, axis = _hits(box, origin, dirs)
        nearer = t < depth
        depth, hit = np.where(nearer, t, depth), np.where(nearer, index, hit)
        hit_axis = np.where(nearer, axis, hit_axis)
    points = origin + dirs * np.where(np.isfinite(depth), depth, 0.0)[..., None]
    colour = np.full((height, width, 3), float(background))
    names = {face.texture for box in boxes for face in box.faces.values()} - {None}
    textures = {name: load_texture(TEXTURES / name) for name in names}
    for index, box in enumerate(boxes):
        for (axis, high), face in box.faces.items():
            entering = (dirs[..., axis] > 0) == bool(high) if box.shell else (dirs[..., axis] < 0) == bool(high)
            on = (hit == index) & (hit_axis == axis) & entering
            colour[on] = _sample(textures.get(face.texture), points[on], axis, face.size) * face.shade
    return colour.clip(0.0, 1.0), depth


def _hits(box: Box, origin: np.ndarray, dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where each ray meets ``box`` (inf where it misses) and the axis of the face it meets there."""
    lo, hi = np.array(box.lo), np.array(box.hi)
    with np.errstate(divide="ignore", invalid="ignore"):
        if box.shell:
            exits = np.where(dirs > 0, (hi - origin) / dirs, (lo - origin) / dirs)
            exits = np.where(np.isfinite(exits), exits, np.inf)
            return exits.min(axis=-1), np.argmin(exits, axis=-1)
        t1, t2 = (lo - origin) / dirs, (hi - origin) / dirs
    entries = np.minimum(t1, t2)
    near, far = np.nanmax(entries, -1), np.nanmin(np.maximum(t1, t2), -1)
    met = (near < far) & (near > 0)
    return np.where(met, near, np.inf), np.nanargmax(np.where(np.isnan(entries), -np.inf, entries), -1)


def _sample(texture: np.ndarray | None, points: np.ndarray, axis: int, size: float) -> np.ndarray:
    """Colours (n, 3) of ``texture`` tiled ``size`` metres a repeat on the plane normal to ``axis`` (None: plaster)."""
    if texture is None:
        return np.full((len(points), 3), 0.88)
    a, b = [k for k in range(3) if k != axis]
    h, w = texture.shape[:2]
    rows = ((-points[:, b] / size) % 1.0 * h).astype(int) % h
    cols = ((points[:, a] / size * h / w) % 1.0 * w).astype(int) % w
    return texture[rows, cols]


def write_capture(
    folder: Path, cams: list[Camera], boxes: list[Box], size: tuple[int, int], downscale: int, background: float = 0.0
) -> None:
    """``boxes`` photographed by ``cams`` (full-size intrinsics) as an LLFF capture in ``folder``
    (poses_bounds.npy, images_<downscale>/ at ``size``)."""
    (folder / f"images_{downscale}").mkdir(parents=True, exist_ok=True)
    rows = []
    for i, cam in enumerate(cams):
        colour, depth = trace(cam, boxes, *size, background=background)
        write_png(folder / f"images_{downscale}" / f"image{i:03d}.png", (colour * 255 + 0.5).astype(np.uint8))
        r = cam.cam_to_world[:3, :3]  # OpenCV columns: right, down, forward; LLFF's: down, right, back
        pose = np.column_stack([r[:, 1], r[:, 0], -r[:, 2], cam.center, [cam.height, cam.width, cam.fx]])
        seen = depth[np.isfinite(depth)]
        rows.append(np.concatenate([pose.ravel(), [0.9 * seen.min(), 1.1 * seen.max()]]))
    np.save(folder / "poses_bounds.npy", np.array(rows))


def fitted_capture(
    name: str,
    settings: dict,
    cams: list[Camera],
    boxes: list[Box],
    *,
    size: tuple[int, int],
    downscale: int,
    iterations: int,
    background: float = 0.0,
) -> Path:
    """The cached folder of the capture ``name`` fitted for ``iterations`` steps (``fit/point_cloud.ply``,
    ``fit/fit_report.json``; made and fitted here first when missing). ``settings`` key the cache."""
    keyed = settings | {"iterations": iterations, "seed": 0}
    folder = CACHE / f"{name}-{hashlib.sha1(json.dumps(keyed, sort_keys=True).encode()).hexdigest()[:12]}"
    if not (folder / "fit" / "point_cloud.ply").is_file():
        print(f"making {name} and fitting it ({iterations} steps) into {folder} (once)", flush=True)
        write_capture(folder / "capture", cams, boxes, size, downscale, background)
        config = FitConfig(iterations=iterations, background=(background,) * 3)
        report = fit_llff(folder / "capture", folder / "fit", downscale=downscale, config=config)
        report.write_json(folder / "fit" / "fit_report.json")
    return folder
