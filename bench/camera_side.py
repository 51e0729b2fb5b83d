"""Where did a capture's cameras stand? The fit *Automatic Views: Front* stands its views by, on the scenes.

    .venv/bin/python bench/camera_side.py [--scenes fern donut guitar playbot]

``core.cameras.viewpoint.fitted_viewpoint``: a trained splat's footprint matches the pixels it was trained from, so
its size grows with its distance from the cameras that saw it; one point and a factor fitted to the opaque splats
(log middle scale = log k + log distance, Huber loss, seven starts), against one size for all (the gain).
Per scene: the gain (how well one viewpoint explains the sizes: a capture seen from one side), the point's and the
farthest splat's (98 %) distance from the middle that way, as shares of the capture's extent; where the cameras are
known (the fern's LLFF poses) the angle between the directions from the middle to the point and to the cameras'
mean, and their distances. Prints a table; writes bench/out/camera_side.json.
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

from gt2gs_blender.core.cameras.files import load_views
from gt2gs_blender.core.cameras.viewpoint import HUBER, QUANTILE, SAMPLE, fitted_viewpoint
from gt2gs_blender.core.scene.files import read_scene

OUT = ROOT / "bench" / "out" / "camera_side.json"


def measure(name: str) -> dict:
    """The row of one scene: the fit's gain, the point, and against the known cameras if any."""
    cameras = None
    if name == "fern":
        folder = fern_fit_dir()
        scene, cameras = read_scene(folder / "point_cloud.ply"), load_views(folder / "cameras.json")
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
        "point": viewpoint.point.tolist(),
        "point_from_middle": float(np.linalg.norm(away)) / viewpoint.extent,
        "farthest_splat_that_way": float(np.quantile(along, 1.0 - QUANTILE)) / viewpoint.extent,
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
    parser.add_argument("--scenes", nargs="+", default=["fern", "donut", "guitar", "playbot"])
    args = parser.parse_args()
    rows = [measure(name) for name in args.scenes]
    print(f"{'scene':8s} {'gain':>6s} {'point/extent':>12s} {'farthest':>8s} {'deg':>6s}")
    for r in rows:
        if r["gain"] is None:
            print(f"{r['scene']:8s} too few opaque splats to fit")
            continue
        degrees = f"{r['degrees_from_cameras']:6.1f}" if "degrees_from_cameras" in r else f"{'':6s}"
        shares = f"{r['point_from_middle']:12.3f} {r['farthest_splat_that_way']:8.3f}"
        print(f"{r['scene']:8s} {r['gain']:6.1%} {shares} {degrees}")
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(json.dumps({"samples": SAMPLE, "huber": HUBER, "rows": rows}, indent=1))
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
