"""How a transfer's cost grows with the number of Gaussians (10k -> 1M) and with the image size.

``python bench/scaling.py [--counts 10000 30000 100000 300000 1000000] [--resolutions 128 256 384 512]``
builds scenes from the shared donut (subsampled, or duplicated with jitter past its 45.6k Gaussians; random
scenes from bench/common.py when ../shared is absent) and times, per scene, the parts whose cost depends on
it: the hidden-Gaussian pass over the views, a stylise step (render, VGG, GT² matching, backward, Adam) and
a correct step (GPB), medians over ``--steps`` steps, at the fast preset's settings. First, the
hidden-Gaussian skip's speed-up on the donut per threshold (``--hidden``), timed interleaved with the run
that keeps every Gaussian. The resolution sweep uses the donut as it is. Prints tables and the log-log slope
of step time against Gaussians (1 = linear), writes bench/out/scaling.json and bench/out/scaling.png.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import torch

from bench.common import random_scene
from gt2gs_blender.core.cameras.generate import auto_views
from gt2gs_blender.core.features.extractor import load_feature_extractor
from gt2gs_blender.core.scene.gaussians import GaussianScene
from gt2gs_blender.core.scene.ply import read_ply
from gt2gs_blender.core.transfer.bank import bank_crop
from gt2gs_blender.core.transfer.content import contributions, hidden_gaussians
from gt2gs_blender.core.transfer.presets import preset
from gt2gs_blender.core.transfer.stylise import Styliser, order_and_link
from gt2gs_blender.core.transfer.texture import load_texture
from gt2gs_blender.core.transfer.texture_bank import build_texture_bank
from gt2gs_blender.core.transfer.views import render_views, view_targets

SHARED = ROOT.parent / "shared"
OUT = ROOT / "bench" / "out"
SCENE = SHARED / "data" / "scenes" / "donut" / "point_cloud.ply"
TEXTURE = SHARED / "data" / "textures" / "herringbone_wood.jpg"
N_VIEWS = 8


def base_scene() -> GaussianScene:
    """The donut at SH degree 0 (what the styliser trains), or a random scene without ../shared."""
    scene = read_ply(SCENE) if SCENE.is_file() else random_scene(45_624, degree=0)
    return scene.with_sh_degree(0)


def resized(scene: GaussianScene, n: int, seed: int = 0) -> GaussianScene:
    """``n`` Gaussians of ``scene``: a random subset, or copies jittered by a tenth of each one's
    largest scale (so duplicates neither coincide nor change the object's look much)."""
    g = torch.Generator().manual_seed(seed)
    if n <= len(scene):
        return scene.subset(torch.randperm(len(scene), generator=g)[:n].sort().values)
    index = torch.arange(n) % len(scene)
    out = scene.subset(index)
    jitter = torch.randn(n, 3, generator=g) * out.scales.max(dim=1, keepdim=True).values * 0.1
    jitter[: len(scene)] = 0.0
    return replace(out, means=out.means + jitter)


def time_steps(scene: GaussianScene, resolution: int, steps: int, extractor, texture: np.ndarray) -> dict[str, Any]:
    """Median seconds of the hidden pass, a stylise step and a correct step on ``scene``."""
    config = preset("fast", resolution=resolution, n_views=N_VIEWS, densify=False, evaluate=False)
    cameras = auto_views(scene, N_VIEWS, width=resolution, height=resolution)
    background = torch.ones(3)
    start = time.perf_counter()
    hidden = hidden_gaussians(scene, cameras, config.hidden_threshold)
    hidden_s = time.perf_counter() - start
    content = render_views(scene, cameras, background, config.backend)
    targets = view_targets(content, scene, extractor, config, config.backend)
    order = order_and_link(targets, content.depths, content.alphas)
    bank = build_texture_bank(
        texture,
        lambda x: extractor(x, scale=1.0),
        extractor_id="scaling",
        n_scales=4,
        n_angles=config.n_angles,
        max_crop=bank_crop(extractor.spec),
    )
    styliser = Styliser(scene, targets, order, bank, extractor, config, background)
    stylise_s, correct_s = [], []
    for _ in range(steps):
        t = time.perf_counter()
        styliser.stylise_step(False)
        stylise_s.append(time.perf_counter() - t)
        t = time.perf_counter()
        styliser.correct_step()
        correct_s.append(time.perf_counter() - t)
    return {
        "n": len(scene),
        "resolution": resolution,
        "hidden_pass_s": hidden_s,
        "hidden": 0 if hidden is None else int(hidden.sum()),
        "stylise_step_s": statistics.median(stylise_s),
        "correct_step_s": statistics.median(correct_s),
        "load": os.getloadavg(),
    }


def hidden_ab(
    scene: GaussianScene, thresholds: list[float], steps: int, extractor, texture: np.ndarray, resolution: int = 256
) -> list[dict[str, Any]]:
    """Step time with the hidden Gaussians left out vs all of them, per threshold: the two stylisers
    step in turn (A, B, A, B, ...) so that a change in the machine's load hits both alike."""
    config = preset("fast", resolution=resolution, densify=False, evaluate=False)
    cameras = auto_views(scene, config.n_views, width=resolution, height=resolution)
    background = torch.ones(3)
    content = render_views(scene, cameras, background, config.backend)
    bank = build_texture_bank(
        texture,
        lambda x: extractor(x, scale=1.0),
        extractor_id="scaling",
        n_scales=4,
        n_angles=config.n_angles,
        max_crop=bank_crop(extractor.spec),
    )
    weight = contributions(scene, cameras, config.backend)

    def styliser(work: GaussianScene) -> Styliser:
        targets = view_targets(content, work, extractor, config, config.backend)
        return Styliser(
            work, targets, order_and_link(targets, content.depths, content.alphas), bank, extractor, config, background
        )

    rows = []
    for threshold in thresholds:
        kept = weight > threshold
        pair = {"all": styliser(scene), "skip": styliser(scene.subset(kept))}
        times: dict[str, list[float]] = {"all": [], "skip": []}
        for _ in range(steps):
            for name, s in pair.items():
                t = time.perf_counter()
                s.stylise_step(False)
                s.correct_step()
                times[name].append(time.perf_counter() - t)
        all_s, skip_s = statistics.median(times["all"]), statistics.median(times["skip"])
        rows.append(
            {
                "threshold": threshold,
                "hidden": int((~kept).sum()),
                "n": len(scene),
                "step_all_s": all_s,
                "step_skip_s": skip_s,
                "speedup": all_s / skip_s,
                "load": os.getloadavg(),
            }
        )
        print(
            f"hidden <= {threshold:g} px: {rows[-1]['hidden']:,} of {len(scene):,} skipped, stylise+correct "
            f"step {all_s:.3f} -> {skip_s:.3f} s ({rows[-1]['speedup']:.2f}x), load {rows[-1]['load'][0]:.1f}",
            flush=True,
        )
    return rows


def slope(xs: list[float], ys: list[float]) -> float:
    """Least-squares slope of log y against log x."""
    return float(np.polyfit(np.log(xs), np.log(ys), 1)[0])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--counts", nargs="*", type=int, default=[10_000, 30_000, 100_000, 300_000, 1_000_000])
    parser.add_argument("--resolutions", nargs="*", type=int, default=[128, 256, 384, 512])
    parser.add_argument("--steps", type=int, default=3)
    parser.add_argument(
        "--hidden",
        nargs="*",
        type=float,
        default=[0.0, 0.1, 1.0],
        help="hidden-Gaussian thresholds (px) to time against no skip, interleaved",
    )
    parser.add_argument("--json", type=Path, default=OUT / "scaling.json")
    parser.add_argument("--png", type=Path, default=OUT / "scaling.png")
    args = parser.parse_args()
    OUT.mkdir(parents=True, exist_ok=True)
    torch.manual_seed(0)
    extractor = load_feature_extractor("auto", SHARED / "weights" if SHARED.is_dir() else None)
    texture = load_texture(TEXTURE) if TEXTURE.is_file() else np.random.default_rng(0).random((256, 256, 3))
    scene = base_scene()
    hidden_rows = hidden_ab(scene, args.hidden, 2 * args.steps, extractor, texture) if args.hidden else []
    columns = ("n", "resolution", "hidden_pass_s", "stylise_step_s", "correct_step_s", "hidden")
    header = " ".join(f"{c:>15}" for c in columns) + f" {'load':>5}"
    by_count, by_resolution = [], []
    print("Gaussians (256 px):\n" + header)
    for n in args.counts:
        by_count.append(time_steps(resized(scene, n), 256, args.steps, extractor, texture))
        print(
            " ".join(
                f"{by_count[-1][c]:>15.3f}" if isinstance(by_count[-1][c], float) else f"{by_count[-1][c]:>15}"
                for c in columns
            )
            + f" {by_count[-1]['load'][0]:>5.1f}",
            flush=True,
        )
    print(f"resolution ({len(scene):,} Gaussians):\n" + header)
    for resolution in args.resolutions:
        by_resolution.append(time_steps(scene, resolution, args.steps, extractor, texture))
        print(
            " ".join(
                f"{by_resolution[-1][c]:>15.3f}"
                if isinstance(by_resolution[-1][c], float)
                else f"{by_resolution[-1][c]:>15}"
                for c in columns
            )
            + f" {by_resolution[-1]['load'][0]:>5.1f}",
            flush=True,
        )
    counts = [r["n"] for r in by_count]
    slopes = {}
    if len(by_count) >= 2:
        slopes.update(
            {part: slope(counts, [r[part] for r in by_count]) for part in ("stylise_step_s", "correct_step_s")}
        )
    large = [r for r in by_count if r["n"] >= 100_000]
    if len(large) >= 2:
        slopes.update(
            {
                f"{part} (>=100k)": slope([r["n"] for r in large], [r[part] for r in large])
                for part in ("stylise_step_s", "correct_step_s")
            }
        )
    if len(by_resolution) >= 2:
        pixels = [r["resolution"] ** 2 for r in by_resolution]
        slopes["stylise_step_s vs pixels"] = slope(pixels, [r["stylise_step_s"] for r in by_resolution])
    for name, value in slopes.items():
        print(
            f"log-log slope of {name}: {value:.2f}"
            + (" (linear or better)" if "pixels" not in name and value <= 1.1 else "")
        )
    args.json.write_text(
        json.dumps(
            {"by_count": by_count, "by_resolution": by_resolution, "slopes": slopes, "hidden_skip": hidden_rows},
            indent=1,
        )
    )
    fig, (left, right) = plt.subplots(1, 2, figsize=(8, 3.2), dpi=100)
    for part, label in (
        ("stylise_step_s", "stylise step"),
        ("correct_step_s", "correct step"),
        ("hidden_pass_s", f"hidden pass ({N_VIEWS} views)"),
    ):
        left.loglog(counts, [r[part] for r in by_count], "o-", label=label)
        right.plot([r["resolution"] for r in by_resolution], [r[part] for r in by_resolution], "o-", label=label)
    if by_count:
        reference = by_count[0]["stylise_step_s"]
        left.loglog(counts, [reference * n / counts[0] for n in counts], ":", color="0.6", label="linear")
    left.set_xlabel("Gaussians")
    right.set_xlabel("image side (px)")
    for ax in (left, right):
        ax.set_ylabel("seconds")
        ax.grid(True, which="both", linewidth=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(args.png)
    plt.close(fig)
    print(f"records: {args.json}\nplot: {args.png}")
    if not all(math.isfinite(v) for v in slopes.values()):
        raise SystemExit("a slope is not finite")


if __name__ == "__main__":
    main()
