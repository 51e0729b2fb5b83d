"""Where did a capture's cameras stand? A cue for views of a capture given without its cameras (measured, not used).

    .venv/bin/python bench/camera_side.py [--scenes fern donut guitar playbot] [--splats 20000]

A trained splat's footprint matches the pixels it was trained from, so its size grows with its distance from the
cameras that saw it. One point ``c`` and a factor ``k`` are fitted to the opaque splats (opacity > 0.5, a random
sample): log(middle scale) = log k + log |x - c|, Huber loss (``DELTA`` in log size), L-BFGS from six starts one
scene extent out along each axis, the best kept. Beside it the same loss about the median size (one size for all):
the fit's gain says how well one viewpoint explains the sizes (a capture seen from one side), ``c`` where it was.
Where the cameras are known (the fern's LLFF poses), the angle between the directions from the scene's middle to
``c`` and to the cameras' mean. Prints a table; writes bench/out/camera_side.json.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))
sys.path.insert(0, str(ROOT))

from recognise_scenes import CAPTURES, DONUT, fern_fit_dir

from gt2gs_blender.core.cameras.files import load_views
from gt2gs_blender.core.scene.files import read_scene
from gt2gs_blender.core.scene.gaussians import GaussianScene

OUT = ROOT / "bench" / "out" / "camera_side.json"
DELTA = 0.5
OPAQUE = 0.5
QUANTILE = 0.02
"""The scene's middle and extent: the box between these quantiles of the splats' centres (floaters aside)."""


def sample(scene: GaussianScene, count: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Centres (n, 3) and log middle scales (n,) of up to ``count`` opaque splats, float64, drawn with seed 0."""
    log_size = torch.sort(scene.scales.detach().double(), dim=1).values[:, 1].log()
    keep = torch.isfinite(log_size) & (scene.opacities.detach().double().reshape(-1) > OPAQUE)
    centres, log_size = scene.means.detach().double()[keep], log_size[keep]
    pick = torch.randperm(len(centres), generator=torch.Generator().manual_seed(0))[:count]
    return centres[pick], log_size[pick]


def viewpoint(
    centres: torch.Tensor, log_size: torch.Tensor, middle: torch.Tensor, extent: float
) -> tuple[torch.Tensor, float]:
    """The point (3,) whose distance best explains the sizes, and the fit's loss."""

    def loss(p: torch.Tensor) -> torch.Tensor:
        residual = log_size - p[3] - (centres - p[:3]).norm(dim=1).clamp_min(1e-12).log()
        return F.huber_loss(residual, torch.zeros_like(residual), delta=DELTA)

    starts = [
        torch.cat([middle + direction * extent, (log_size.median() - math.log(extent)).reshape(1)])
        for direction in torch.cat([torch.eye(3), -torch.eye(3)]).double()
    ]
    point, value = min((minimised(loss, start) for start in starts), key=lambda fit: fit[1])
    return point[:3], value


def minimised(loss: Callable[[torch.Tensor], torch.Tensor], start: torch.Tensor) -> tuple[torch.Tensor, float]:
    """``loss``'s minimum from ``start`` by L-BFGS: the parameters and the loss there."""
    p = start.clone().requires_grad_(True)
    optimiser = torch.optim.LBFGS([p], max_iter=300, line_search_fn="strong_wolfe")

    def closure() -> torch.Tensor:
        optimiser.zero_grad()
        value = loss(p)
        value.backward()
        return value

    optimiser.step(closure)
    with torch.no_grad():
        return p.detach(), float(loss(p))


def measure(name: str, count: int) -> dict:
    """The row of one scene: the fit's and the flat loss, the point, and against the known cameras if any."""
    cameras = None
    if name == "fern":
        folder = fern_fit_dir()
        scene, cameras = read_scene(folder / "point_cloud.ply"), load_views(folder / "cameras.json")
    else:
        scene = read_scene(CAPTURES.get(name, DONUT))
    centres, log_size = sample(scene, count)
    lo, hi = (torch.quantile(centres, q, dim=0) for q in (QUANTILE, 1.0 - QUANTILE))
    middle, extent = (lo + hi) / 2.0, float((hi - lo).norm())
    point, fitted = viewpoint(centres, log_size, middle, extent)
    flat = float(F.huber_loss(log_size, torch.full_like(log_size, float(log_size.median())), delta=DELTA))
    away = point - middle
    along = (centres - middle) @ (away / away.norm())
    row = {
        "scene": name,
        "splats": len(centres),
        "fit_loss": fitted,
        "flat_loss": flat,
        "gain": 1.0 - fitted / flat,
        "point": point.tolist(),
        "point_from_middle": float(away.norm()) / extent,
        "farthest_splat_that_way": float(along.max()) / extent,
    }
    if cameras is not None:
        mean = torch.tensor(np.mean([c.center for c in cameras], axis=0))
        truth = mean - middle
        cosine = float(away @ truth / (away.norm() * truth.norm()))
        row["degrees_from_cameras"] = math.degrees(math.acos(max(-1.0, min(1.0, cosine))))
        row["from_cameras_mean"] = float((point - mean).norm()) / extent
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenes", nargs="+", default=["fern", "donut", "guitar", "playbot"])
    parser.add_argument("--splats", type=int, default=20_000)
    args = parser.parse_args()
    rows = [measure(name, args.splats) for name in args.scenes]
    print(f"{'scene':8s} {'fit':>6s} {'flat':>6s} {'gain':>6s} {'point/extent':>12s} {'farthest':>8s} {'deg':>6s}")
    for r in rows:
        degrees = f"{r['degrees_from_cameras']:6.1f}" if "degrees_from_cameras" in r else f"{'':6s}"
        print(
            f"{r['scene']:8s} {r['fit_loss']:6.3f} {r['flat_loss']:6.3f} {r['gain']:6.1%} "
            f"{r['point_from_middle']:12.3f} {r['farthest_splat_that_way']:8.3f} {degrees}"
        )
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(json.dumps({"splats": args.splats, "delta": DELTA, "rows": rows}, indent=1))
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
