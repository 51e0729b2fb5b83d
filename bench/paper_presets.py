"""Issue 41's measure of the paper presets: ``paper-llff`` before and after issue 41, at a CPU-sized short
schedule, on the donut and the fern (bench/recognise_scenes.py's scenes and transfer views).

``python bench/paper_presets.py [--scenes donut fern] [--texture herringbone_wood] [--scale 0.1]
[--resolution 256] [--variants before after] [--fern-iterations N] [--tag paper_presets]``

Both variants run on today's engine, one after the other in this process. ``after`` is ``paper-llff`` as it is;
``before`` is it with the values the preset held before issue 41 (20 rounds of GT² + correct, colour rate 0.02,
densification every 25 steps above 2e-4 up to 1.5x, no NNFM half-rounds, no large-splat pruning): every other
difference of the old code was a setting too, or nothing (the bank crop of the VGG-19 these machines have is
64 px either way). The schedule is scaled by ``--scale`` (the rounds kept, every phase's steps and the
densification interval scaled, so each run densifies as often as the full schedule), the views at
``--resolution``. Reports the run's content measures (``ssim`` of the frames, ``object_ssim`` on the
original's pixels), texture match (start and end), Gaussians and seconds (inflated by the machine's load: compare
ratios). Writes bench/out/<tag>.json.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))
sys.path.insert(0, str(ROOT))

import recognise_scenes
from recognise_scenes import SHARED, load_bench_scene

from gt2gs_blender.core.transfer.pipeline import transfer
from gt2gs_blender.core.transfer.presets import LLFF_ROUND, paper_schedule, preset

OUT = ROOT / "bench" / "out"
BEFORE: dict[str, Any] = dict(
    rounds=20,
    nnfm_half=False,
    lr=0.02,
    densify_every=25,
    densify_grad_threshold=2e-4,
    densify_max_growth=1.5,
    prune_large=False,
)
"""paper-llff's values before issue 41 that differ from today's (its step totals were today's)."""
METRICS = ("ssim", "object_ssim", "texture_match_start", "texture_match", "lpips")


def schedule(variant: str, scale: float) -> dict[str, Any]:
    """The variant's settings with its schedule scaled by ``scale``."""
    full = {**paper_schedule(10, LLFF_ROUND), **(BEFORE if variant == "before" else {})}
    return {
        **full,
        "stylise_steps": round(full["stylise_steps"] * scale),
        "correct_steps": round(full["correct_steps"] * scale),
        "densify_every": max(1, round(full["densify_every"] * scale)),
    }


def run(scene_name: str, variant: str, texture: Path, scale: float, resolution: int, cache: str) -> dict[str, Any]:
    """One transfer of ``variant`` on ``scene_name``; its settings, metrics, size and time."""
    bench = load_bench_scene(scene_name, resolution)
    overrides = schedule(variant, scale)
    config = preset(
        "paper-llff",
        resolution=resolution,
        weights_path=str(SHARED / "weights"),
        cache_dir=cache,
        background=bench.background,
        **overrides,
    )
    start = time.perf_counter()
    result = transfer(bench.scene, texture, bench.transfer_views, config)
    report = result.report
    metrics = report["metrics"] or {}
    return {
        "scene": scene_name,
        "variant": variant,
        "settings": overrides,
        "n_gaussians_start": len(bench.scene),
        "n_gaussians": report["n_gaussians"],
        "densified": len(report["stylise"]["densified"]),
        "seconds": time.perf_counter() - start,
        "stage_seconds": report["stage_seconds"],
        "weights": report["weights"].get("spec"),
        **{name: metrics.get(name) for name in METRICS},
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenes", nargs="+", default=["donut", "fern"])
    parser.add_argument("--texture", default="herringbone_wood")
    parser.add_argument("--scale", type=float, default=0.1)
    parser.add_argument("--resolution", type=int, default=256)
    parser.add_argument("--variants", nargs="+", default=["before", "after"], choices=["before", "after"])
    parser.add_argument("--fern-iterations", type=int, help="a shorter fern fit than recognise_scenes' (cached apart)")
    parser.add_argument("--tag", default="paper_presets", help="writes bench/out/<tag>.json")
    args = parser.parse_args()
    if args.fern_iterations:
        recognise_scenes.FERN_FIT = {**recognise_scenes.FERN_FIT, "iterations": args.fern_iterations}
    texture = next((SHARED / "data" / "textures").glob(f"{args.texture}.*"))
    rows = []
    with tempfile.TemporaryDirectory() as cache:
        for scene_name in args.scenes:
            for variant in args.variants:
                rows.append(run(scene_name, variant, texture, args.scale, args.resolution, cache))
                row = rows[-1]
                print(
                    f"{scene_name:6s} {variant:6s} ssim {row['ssim']:.3f} object_ssim {row['object_ssim']:.3f} "
                    f"texture match {row['texture_match_start']:.3f} -> {row['texture_match']:.3f} "
                    f"splats {row['n_gaussians_start']:,} -> {row['n_gaussians']:,} {row['seconds']:.0f} s",
                    flush=True,
                )
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / f"{args.tag}.json").write_text(json.dumps({"args": vars(args), "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
