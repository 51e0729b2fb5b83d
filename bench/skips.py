"""Each skip of the ``fast`` preset on vs off, on the shared donut: speed-up and quality change.

``python bench/skips.py [--skips hidden plateau ...]`` runs the ``fast`` preset (16 automatic views at 256
px, herringbone wood) once as the baseline, then once per skip with that skip switched the other way
(default-on skips are switched off, default-off skips on), one after the other in this process, after an
untimed ``preview`` run (first-call costs); ``--rounds R`` repeats the sequence (baseline first in each
round) and keeps the fastest run of each (the machine has slow spells of 2-3x: the minimum is the estimate);
every run builds its bank into a fresh cache and starts with the in-process content cache empty, except
``caches``, which repeats the baseline with both caches warm. ``angles`` is a pair of its own on the
woven-straw photo (herringbone is strongly oriented, so the adaptive count is the full 72 there: nothing to
skip). ``sh`` times the content renders of the donut padded to SH degree 3 with zero bands, rendered at
degree 3 vs the used degree 0 (the donut itself has no bands above DC; renders are bit-identical, so no
quality change). Prints the table (speed-up = time without the skip / time with it; quality deltas = with
minus without, texture match and LT RMSE lower is better, SSIM higher) with the load average, writes
bench/out/skips.json.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import torch

from gt2gs_blender.core.cameras.generate import auto_views
from gt2gs_blender.core.render import available_backends
from gt2gs_blender.core.scene.ply import read_ply
from gt2gs_blender.core.transfer.content import clear_caches
from gt2gs_blender.core.transfer.pipeline import transfer
from gt2gs_blender.core.transfer.presets import preset
from gt2gs_blender.core.transfer.views import render_views

SHARED = ROOT.parent / "shared"
OUT = ROOT / "bench" / "out"
SCENE = SHARED / "data" / "scenes" / "donut" / "point_cloud.ply"
TEXTURES = SHARED / "data" / "textures"
HERRINGBONE, STRAW = TEXTURES / "herringbone_wood.jpg", TEXTURES / "woven_straw.jpg"
METRICS = ("texture_match", "ssim", "lt_rmse")
SKIPS: dict[str, tuple[str, dict[str, Any], dict[str, Any], Path]] = {
    # name: (what, overrides with the skip ON, overrides with it OFF, texture); one side is the preset's
    "hidden": ("hidden Gaussians frozen (<= 0.1 px)", {"skip_hidden": True}, {"skip_hidden": False}, HERRINGBONE),
    "vgg_scale": ("VGG on renders x0.5", {"feature_scale": 0.5}, {"feature_scale": 1.0}, HERRINGBONE),
    "plateau": (
        "stop phases at a loss plateau (16 steps, 1 %)",
        {"plateau_window": 16, "plateau_tol": 0.01},
        {"plateau_window": 0},
        HERRINGBONE,
    ),
    "dedup": (
        "bank: merge twins (cos > 0.95, per depth group)",
        {"dedup_threshold": 0.95},
        {"dedup_threshold": 0.0},
        HERRINGBONE,
    ),
    "pca": ("bank: match on 64 PCA channels of 384", {"match_channels": 64}, {"match_channels": 0}, HERRINGBONE),
    "drop_views": ("drop views adding < 2 % coverage", {"drop_views": True}, {"drop_views": False}, HERRINGBONE),
    "angles": (
        "bank: angle count from anisotropy (woven straw)",
        {"adaptive_angles": True},
        {"adaptive_angles": False},
        STRAW,
    ),
    "reuse": (
        "colour-only steps redrawn from kept compositing weights",
        {"reuse_weights": True},
        {"reuse_weights": False},
        HERRINGBONE,
    ),
    "window": (
        "VGG run only near the splats, the backdrop's features elsewhere",
        {"feature_window": True},
        {"feature_window": False},
        HERRINGBONE,
    ),
    "caches": ("bank on disk + content renders reused (2nd run)", {}, {}, HERRINGBONE),
}


def run(overrides: dict[str, Any], texture: Path, cache_dir: str, warm: bool = False) -> dict[str, Any]:
    """One end-to-end ``fast`` transfer; with ``warm`` a first run fills the caches, the second is timed."""
    config = preset("fast", weights_path=str(SHARED / "weights"), cache_dir=cache_dir, evaluate=True, **overrides)
    scene = read_ply(SCENE)
    clear_caches()
    if warm:
        transfer(scene, str(texture), None, config)
    load = os.getloadavg()
    start = time.perf_counter()
    report = transfer(scene, str(texture), None, config).report
    return {
        "overrides": overrides,
        "texture": texture.name,
        "seconds": time.perf_counter() - start,
        "stage_seconds": report["stage_seconds"],
        "metrics": {m: report["metrics"][m] for m in METRICS},
        "skips": report["skips"],
        "stylise": {k: v for k, v in report["stylise"].items() if k != "densified"},
        "load": load,
        "load_after": os.getloadavg(),
    }


def _keep_fastest(table: dict[str, dict[str, Any]], key: str, record: dict[str, Any]) -> None:
    """Store ``record`` under ``key``, keeping the fastest run's record and every run's seconds."""
    seconds = table[key]["seconds_runs"] + [record["seconds"]] if key in table else [record["seconds"]]
    if key not in table or record["seconds"] < table[key]["seconds"]:
        table[key] = record
    table[key]["seconds_runs"] = seconds


def sh_timing(repeats: int = 3) -> dict[str, Any]:
    """Content renders of the donut padded to SH degree 3 (zero bands): all bands vs the used ones."""
    scene = read_ply(SCENE).with_sh_degree(3)
    cameras = auto_views(scene, 16, width=256, height=256)
    background = torch.ones(3, dtype=scene.dtype)
    times = {}
    for degree in (3, 0, 3, 0) * ((repeats + 1) // 2):
        start = time.perf_counter()
        views = render_views(scene, cameras, background, "auto", degree)
        times.setdefault(degree, []).append(time.perf_counter() - start)
    same = all(
        torch.equal(a, b)
        for a, b in zip(render_views(scene, cameras, background, "auto", 3).premultiplied, views.premultiplied)
    )
    return {"off_s": min(times[3]), "on_s": min(times[0]), "identical": same, "load": os.getloadavg()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--skips", nargs="+", choices=(*SKIPS, "sh"), default=[*SKIPS, "sh"])
    parser.add_argument("--rounds", type=int, default=1, help="interleaved repeats; times are the minimum")
    parser.add_argument("--json", type=Path, default=OUT / "skips.json")
    args = parser.parse_args()
    OUT.mkdir(parents=True, exist_ok=True)
    defaults = preset("fast")
    records: dict[str, Any] = {"backends": available_backends("cpu")}  # the kernel loaded once, for every run
    print(f"rasterizer backends: {records['backends']}", flush=True)
    with tempfile.TemporaryDirectory() as cache:

        def fresh_run(overrides: dict[str, Any], texture: Path, warm: bool = False) -> dict[str, Any]:
            with tempfile.TemporaryDirectory(dir=cache) as fresh:
                record = run(overrides, texture, fresh, warm)
            print(
                f"  {overrides or 'fast'} {texture.stem}: {record['seconds']:.1f} s, load {record['load'][0]:.1f}, "
                + " ".join(f"{m} {record['metrics'][m]:.4f}" for m in METRICS),
                flush=True,
            )
            return record

        warm_up = preset("preview", weights_path=str(SHARED / "weights"), cache_dir=cache)
        transfer(read_ply(SCENE), str(HERRINGBONE), None, warm_up)  # untimed: first-call costs (kernels, pools)
        baselines: dict[str, dict[str, Any]] = {}
        others: dict[str, dict[str, Any]] = {}
        for _ in range(args.rounds):  # interleaved rounds; every time is the minimum over the rounds
            for name in args.skips:
                if name == "sh":
                    continue
                what, on, off, texture = SKIPS[name]
                default_on = name == "caches" or all(getattr(defaults, k) == v for k, v in on.items())
                if texture.name not in baselines or name == args.skips[0]:
                    _keep_fastest(baselines, texture.name, fresh_run({}, texture))
                other = (
                    fresh_run({}, texture, warm=True)
                    if name == "caches"
                    else fresh_run(off if default_on else on, texture)
                )
                _keep_fastest(others, name, other)
                records[name] = {"what": what, "default_on": default_on, "texture": texture.name}
        for name, other in others.items():
            record = records[name]
            base = baselines[record["texture"]]
            with_skip, without = (base, other) if record["default_on"] and name != "caches" else (other, base)
            record.update(on=with_skip, off=without)
        if "sh" in args.skips:
            records["sh"] = sh_timing()
    print(
        f"\n{'skip':<50} {'default':>7} {'s off':>6} {'s on':>6} {'speed-up':>8} "
        f"{'d tex match':>11} {'d SSIM':>7} {'d LT RMSE':>9} {'load':>5}"
    )
    for name, r in records.items():
        if name == "backends":
            continue
        if name == "sh":
            print(
                f"{'SH bands unused (content renders, deg 3 zero)':<50} {'on':>7} {r['off_s']:>6.2f} "
                f"{r['on_s']:>6.2f} {r['off_s'] / r['on_s']:>8.2f} {'0 (identical)' if r['identical'] else '?':>11}"
                f" {'':>7} {'':>9} {r['load'][0]:>5.1f}"
            )
            continue
        on, off = r["on"], r["off"]
        d = {m: on["metrics"][m] - off["metrics"][m] for m in METRICS}
        print(
            f"{r['what']:<50} {'on' if r['default_on'] else 'off':>7} {off['seconds']:>6.1f} {on['seconds']:>6.1f} "
            f"{off['seconds'] / on['seconds']:>8.2f} {d['texture_match']:>+11.4f} {d['ssim']:>+7.4f} "
            f"{d['lt_rmse']:>+9.4f} {on['load'][0]:>5.1f}"
        )
    args.json.write_text(json.dumps(records, indent=1))
    print(f"records: {args.json}")


if __name__ == "__main__":
    main()
