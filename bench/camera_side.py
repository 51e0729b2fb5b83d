"""Where did a capture's cameras stand? The fit *Automatic Views: Front* stands its views by, on the scenes.

    .venv/bin/python bench/camera_side.py [--scenes fern donut guitar playbot]

``core.cameras.viewpoint.fitted_viewpoint``: a trained splat's footprint matches the pixels it was trained from, so
its size grows with its distance from the cameras that saw it; one point and a factor fitted to the opaque splats
(log middle scale = log k + log distance, Huber loss, seven starts), against one size for all (the gain).
Per scene: the gain (how well one viewpoint explains the sizes: a capture seen from one side), the point's and the
farthest splat's (98 %) distance from the middle that way, as shares of the capture's extent; the cone (how wide
the opaque splats spread, seen from the point); where the cameras are known (the fern's LLFF poses) the angle
between the directions from the middle to the point and to the cameras' mean, and their distances; and the views
*Automatic Views: Auto* draws.

Beside the shared scenes, synthetic captures whose cameras are known (``bench/traced.py``: ray-traced, fitted by
``fit``, cached): two seen from the front (``front-room``: the room of ``bench/room.py`` from one end, looking down
its length at a box before the far wall; ``front-close``: its cabinet and corner from a metre away), two objects seen
all round (a toy-brick box on a herringbone slab, from a ring 15-35 degrees up, ``object-ring``, and from a dome 20-70
degrees up, ``object-dome``) and the room from inside (``room``). Prints a table; writes bench/out/camera_side.json.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))
sys.path.insert(0, str(ROOT))

from recognise_scenes import CAPTURES, DONUT, fern_fit_dir
from room import CABINET, DOWNSCALE, HEIGHT, ROOM, WIDTH, cameras_inside, fitted_room
from room import ITERATIONS as ROOM_ITERATIONS
from traced import Box, fitted_capture, one_look

from gt2gs_blender.core.cameras.camera import Camera
from gt2gs_blender.core.cameras.files import load_views
from gt2gs_blender.core.cameras.generate import chosen_kind
from gt2gs_blender.core.cameras.poses import look_at
from gt2gs_blender.core.cameras.viewpoint import HUBER, OPAQUE, QUANTILE, SAMPLE, Viewpoint, fitted_viewpoint
from gt2gs_blender.core.scene.files import read_scene
from gt2gs_blender.core.scene.gaussians import GaussianScene

OUT = ROOT / "bench" / "out" / "camera_side.json"
SHARED_SCENES = ["fern", "donut", "guitar", "playbot"]
SYNTHETIC = ["front-room", "front-close", "object-ring", "object-dome", "room"]
ITERATIONS = 1500
"""Steps each synthetic capture is fitted for (the fern's own fit's)."""
PLINTH = Box((-0.3, -0.6, 0.0), (0.3, 0.0, 0.9), one_look("honeycomb.jpg", 0.4, (0.7, 0.8, 0.9)))
"""A box standing in the room's middle: a front capture's near thing before its far wall."""
OBJECT = Box((-0.3, -0.3, 0.0), (0.3, 0.3, 0.9), one_look("toy_bricks.jpeg", 0.3, (0.7, 0.8, 0.95)))
SLAB = Box((-1.0, -1.0, -0.05), (1.0, 1.0, 0.0), one_look("herringbone_wood.jpg", 0.6, (0.6, 0.6, 0.85)))
"""An object on its patch of ground, seen all round over black."""
FRONT_VIEWS, OBJECT_VIEWS = 20, 36
CONE_QUANTILE = 0.95
"""The cone: this quantile of the opaque splats' angles off the middle's direction, seen from the fitted point."""


def front_cameras(
    eye: tuple[float, float, float], spread: tuple[float, float], target: tuple[float, float, float]
) -> list[Camera]:
    """``FRONT_VIEWS`` cameras on a spiral ``spread`` metres wide and high about ``eye`` (across the look), all
    looking at ``target``, as a hand-held forward-facing capture (LLFF's) stands."""
    look = np.subtract(target, eye) / np.linalg.norm(np.subtract(target, eye))
    across = np.cross(look, [0.0, 0.0, 1.0])
    across /= np.linalg.norm(across)
    upward = np.cross(across, look)
    cams = []
    for i in range(FRONT_VIEWS):
        turn, reach = 4.0 * math.pi * i / FRONT_VIEWS, 0.4 + 0.6 * i / FRONT_VIEWS
        at = np.add(eye, reach * (spread[0] * math.cos(turn) * across + spread[1] * math.sin(turn) * upward))
        cams.append(look_at(at, target, width=WIDTH * DOWNSCALE, height=HEIGHT * DOWNSCALE, fov_deg=60.0))
    return cams


def object_cameras(elevations: list[float]) -> list[Camera]:
    """``OBJECT_VIEWS`` cameras 2.4 m from the object's middle, evenly round it, at ``elevations`` (degrees) in turn."""
    middle, cams = np.array([0.0, 0.0, 0.45]), []
    for i in range(OBJECT_VIEWS):
        turn, up = 2.0 * math.pi * i / OBJECT_VIEWS, math.radians(elevations[i % len(elevations)])
        at = middle + 2.4 * np.array([math.cos(turn) * math.cos(up), math.sin(turn) * math.cos(up), math.sin(up)])
        cams.append(look_at(at, middle, width=WIDTH * DOWNSCALE, height=HEIGHT * DOWNSCALE, fov_deg=50.0))
    return cams


def synthetic(name: str) -> tuple[Path, list[Camera]]:
    """The cached fit of the synthetic capture ``name`` and the cameras it was photographed from."""
    if name == "room":
        return fitted_room(ROOM_ITERATIONS) / "fit" / "point_cloud.ply", cameras_inside()
    looks = {
        "front-room": (front_cameras((-2.1, 0.0, 1.4), (0.35, 0.2), (2.5, 0.0, 0.9)), [ROOM, CABINET, PLINTH]),
        "front-close": (front_cameras((0.6, 0.9, 1.0), (0.25, 0.15), (2.5, 1.4, 0.7)), [ROOM, CABINET]),
        "object-ring": (object_cameras([15.0, 35.0]), [OBJECT, SLAB]),
        "object-dome": (object_cameras([20.0, 45.0, 70.0, 30.0, 60.0]), [OBJECT, SLAB]),
    }
    cams, boxes = looks[name]
    settings = {"cameras": [c.cam_to_world.round(6).tolist() for c in cams], "boxes": [(b.lo, b.hi) for b in boxes]}
    folder = fitted_capture(
        name, settings, cams, boxes, size=(WIDTH, HEIGHT), downscale=DOWNSCALE, iterations=ITERATIONS
    )
    return folder / "fit" / "point_cloud.ply", cams


def cone_deg(scene: GaussianScene, viewpoint: Viewpoint) -> float:
    """How wide (degrees) the opaque splats spread seen from the fitted point: ``CONE_QUANTILE`` of their angles off
    the direction to the capture's middle (a front capture's stay within its cameras' field of view)."""
    opaque = scene.opacities.detach().reshape(-1).numpy() > OPAQUE
    rays = scene.means.detach().double().numpy()[opaque] - viewpoint.point
    axis = (viewpoint.middle - viewpoint.point) / max(float(np.linalg.norm(viewpoint.middle - viewpoint.point)), 1e-12)
    cosines = (rays @ axis) / np.maximum(np.linalg.norm(rays, axis=1), 1e-12)
    return float(np.degrees(np.arccos(np.clip(np.quantile(cosines, 1.0 - CONE_QUANTILE), -1.0, 1.0))))


def measure(name: str) -> dict:
    """The row of one scene: the fit's gain, the point, and against the known cameras if any."""
    cameras = None
    if name == "fern":
        folder = fern_fit_dir()
        scene, cameras = read_scene(folder / "point_cloud.ply"), load_views(folder / "cameras.json")
    elif name in SYNTHETIC:
        ply, cameras = synthetic(name)
        scene = read_scene(ply)
    else:
        scene = read_scene(CAPTURES.get(name, DONUT))
    viewpoint = fitted_viewpoint(scene)
    if viewpoint is None:
        return {"scene": name, "gain": None}
    away = viewpoint.point - viewpoint.middle
    along = (scene.means.detach().double().numpy() - viewpoint.middle) @ viewpoint.direction
    row = {
        "scene": name,
        "gain": viewpoint.gain,
        "inside": viewpoint.inside,
        "auto_kind": chosen_kind(scene, "auto"),
        "point": viewpoint.point.tolist(),
        "point_from_middle": float(np.linalg.norm(away)) / viewpoint.extent,
        "farthest_splat_that_way": float(np.quantile(along, 1.0 - QUANTILE)) / viewpoint.extent,
        "cone_deg": cone_deg(scene, viewpoint),
    }
    if cameras is not None:
        mean = np.mean([c.center for c in cameras], axis=0)
        truth = mean - viewpoint.middle
        cosine = float(away @ truth / (np.linalg.norm(away) * np.linalg.norm(truth)))
        row["degrees_from_cameras"] = math.degrees(math.acos(max(-1.0, min(1.0, cosine))))
        row["from_cameras_mean"] = float(np.linalg.norm(viewpoint.point - mean)) / viewpoint.extent
        row["cameras_from_middle"] = float(np.linalg.norm(truth)) / viewpoint.extent
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenes", nargs="+", default=SHARED_SCENES + SYNTHETIC, choices=SHARED_SCENES + SYNTHETIC)
    args = parser.parse_args()
    rows = [measure(name) for name in args.scenes]
    print(f"{'scene':11s} {'gain':>6s} {'point/extent':>12s} {'farthest':>8s} {'deg':>6s} {'cone':>6s} {'auto':>6s}")
    for r in rows:
        if r["gain"] is None:
            print(f"{r['scene']:11s} too few opaque splats to fit")
            continue
        degrees = f"{r['degrees_from_cameras']:6.1f}" if "degrees_from_cameras" in r else f"{'':6s}"
        shares = f"{r['point_from_middle']:12.3f} {r['farthest_splat_that_way']:8.3f}"
        print(f"{r['scene']:11s} {r['gain']:6.1%} {shares} {degrees} {r['cone_deg']:6.1f} {r['auto_kind']:>6s}")
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(json.dumps({"samples": SAMPLE, "huber": HUBER, "rows": rows}, indent=1))
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
