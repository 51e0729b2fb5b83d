"""One texture transfer, timed: a scene x texture x preset -> seconds per stage, peak MiB, quality.

``python bench/transfer.py [--preset fast] [--set key=value ...] [--profile] [--warm-bank]`` runs the shared
donut with the herringbone-wood photo by default, prints a table and writes bench/out/transfer_<preset>.json.
``--tile K`` lays K copies of the scene side by side across its two widest axes, a capture of millions of
splats made of a real one (the robot x 6: 3,000,000). ``--backends cpu,numba,torch [--rounds R]`` runs the
transfer once per rasterizer backend, the backends interleaved, R rounds, in this one process, and adds a
table of their times side by side with each one's median ratio to the first backend's time in the same round.
The texture bank is built into a fresh cache unless ``--warm-bank`` (so the time is end to end: weights, bank,
colour transfer, stylisation, GPB, metrics). ``--profile`` runs under cProfile and splits the time into render
forward/backward, VGG forward, the other backward (VGG and losses), matching, the optimiser and the correct
phases. Timings on a shared machine are noisy: the load average is printed and stored beside them.
"""

from __future__ import annotations

import argparse
import cProfile
import json
import math
import os
import pstats
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.common import parse_overrides
from gt2gs_blender.core.scene.files import read_scene
from gt2gs_blender.core.scene.gaussians import GaussianScene, concat
from gt2gs_blender.core.transfer.metrics import peak_memory_mib
from gt2gs_blender.core.transfer.pipeline import transfer
from gt2gs_blender.core.transfer.presets import preset

SHARED = ROOT.parent / "shared"
OUT = ROOT / "bench" / "out"
DEFAULT_SCENE = SHARED / "data" / "scenes" / "donut" / "point_cloud.ply"
DEFAULT_TEXTURE = SHARED / "data" / "textures" / "herringbone_wood.jpg"
METRICS = (
    "texture_match",
    "texture_match_start",
    "object_ssim",
    "object_ssim_blurred",
    "ssim",
    "st_rmse",
    "lt_rmse",
    "st_lpips",
    "lt_lpips",
)
PROFILE_PARTS: dict[str, tuple[tuple[str, str], ...]] = {
    "stylise phases": (("stylise.py", "stylise_step"),),
    "  render fwd (stylise)": (),
    "  VGG fwd": (("extractor.py", "forward"),),
    "  matching (GT2 targets)": (("gt2.py", "match_with_prior"),),
    "  backward, all": (("_tensor.py", "backward"),),
    "    rasterizer backward": (("cpu_backend.py", "backward"), ("torch_backend.py", "backward")),
    "  optimiser step": (("optim.py", "step"),),
    "correct phases (GPB)": (("stylise.py", "correct_step"),),
    "densification": (("densify.py", "densify_and_prune"),),
    "render fwd, all": (("render/__init__.py", "render"),),
    "content renders + targets": (("views.py", "view_targets"),),
    "prior links": (("stylise.py", "order_and_link"),),
    "bank build": (("bank.py", "build_bank"),),
    "metrics (finish)": (("pipeline.py", "_evaluate"),),
}
"""Profile rows: the summed cumulative time of the listed (file suffix, function) pairs; a call
nested in another listed one of the same row is not counted twice (cProfile's cumulative time)."""


def profile_rows(stats: pstats.Stats) -> dict[str, float]:
    """Seconds per :data:`PROFILE_PARTS` row from a cProfile run."""
    table: dict[tuple[str, str], tuple[float, float]] = {}
    for (filename, _, name), (_, _, tottime, cumtime, _) in stats.stats.items():  # type: ignore[attr-defined]
        key = (filename.replace(os.sep, "/"), name)
        total, _ = table.get(key, (0.0, 0.0))
        table[key] = (total + cumtime, tottime)
    rows = {}
    for label, wanted in PROFILE_PARTS.items():
        rows[label] = sum(
            cum
            for (path, name), (cum, _) in table.items()
            if any(path.endswith(suffix) and name == fn for suffix, fn in wanted)
        )
    rows["  render fwd (stylise)"] = _render_in(stats, "stylise_step")
    return rows


def _render_in(stats: pstats.Stats, caller: str) -> float:
    """Cumulative seconds of the rasterizer's ``render`` when called from ``caller``."""
    for (filename, _, name), (_, _, _, _, callers) in stats.stats.items():  # type: ignore[attr-defined]
        if filename.replace(os.sep, "/").endswith("render/__init__.py") and name == "render":
            return sum(v[3] for (_, _, fn), v in callers.items() if fn == caller)
    return 0.0


def run(args: argparse.Namespace, overrides: dict[str, Any], cache_dir: str | None) -> dict[str, Any]:
    """One transfer; the record stored in the JSON."""
    config = preset(args.preset, weights_path=str(args.weights), **overrides)
    if cache_dir is not None:
        config = config.with_overrides(cache_dir=cache_dir)
    scene = tiled(read_scene(args.scene), args.tile)
    load_before = os.getloadavg()
    profiler = cProfile.Profile() if args.profile else None
    start = time.perf_counter()
    if profiler is not None:
        profiler.enable()
    result = transfer(scene, str(args.texture), args.views, config)
    if profiler is not None:
        profiler.disable()
    seconds = time.perf_counter() - start
    report = result.report
    record = {
        "scene": str(args.scene),
        "texture": str(args.texture),
        "preset": args.preset,
        "overrides": overrides,
        "seconds": seconds,
        "stage_seconds": report["stage_seconds"],
        "peak": peak_memory_mib(report["device"]),
        "n_gaussians_start": len(scene),
        "n_gaussians": report["n_gaussians"],
        "n_views": report["n_views"],
        "image_size": report["image_size"],
        "bank": report["bank"],
        "metrics": report["metrics"],
        "skips": report.get("skips"),
        "stylise": {k: v for k, v in report["stylise"].items() if k != "densified"},
        "load_before": load_before,
        "load_after": os.getloadavg(),
        "cpu_count": os.cpu_count(),
    }
    if profiler is not None:
        record["profile"] = profile_rows(pstats.Stats(profiler))
    return record


def tiled(scene: GaussianScene, copies: int) -> GaussianScene:
    """``copies`` of ``scene`` in a near-square grid across its two widest axes, a tenth of its width apart."""
    if copies <= 1:
        return scene
    low, high = scene.bounds(0.99)
    extent = (high - low).detach()
    wide = torch.argsort(extent, descending=True)[:2].tolist()
    columns = math.ceil(math.sqrt(copies))
    copied = []
    for k in range(copies):
        offset = torch.zeros(3, dtype=scene.dtype, device=scene.device)
        offset[wide[0]] = 1.1 * extent[wide[0]] * (k % columns)
        offset[wide[1]] = 1.1 * extent[wide[1]] * (k // columns)
        copied.append(GaussianScene(**{**scene.tensors(), "means": scene.means + offset}))
    return concat(copied)


def print_record(record: dict[str, Any]) -> None:
    """The table: stages, total, memory, metrics, and the profile when there is one."""
    print(
        f"{Path(record['scene']).parent.name} x {Path(record['texture']).stem} x {record['preset']} "
        f"{record['overrides'] or ''}  ({record['n_views']} views, {record['image_size'][0]} px, "
        f"{record['n_gaussians_start']:,} -> {record['n_gaussians']:,} Gaussians)"
    )
    for stage, s in record["stage_seconds"].items():
        print(f"  {stage:<28} {s:>8.1f} s")
    print(
        f"  {'total':<28} {record['seconds']:>8.1f} s   peak RSS {record['peak']['rss_peak_mib']:.0f} MiB   "
        f"load {record['load_before'][0]:.1f} -> {record['load_after'][0]:.1f} on {record['cpu_count']} cores"
    )
    metrics = record["metrics"] or {}
    print("  " + "  ".join(f"{m} {metrics[m]:.4f}" for m in METRICS if metrics.get(m) is not None))
    for label, s in record.get("profile", {}).items():
        print(f"  {label:<28} {s:>8.1f} s  {100 * s / record['seconds']:>5.1f} %")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", type=Path, default=DEFAULT_SCENE)
    parser.add_argument("--texture", type=Path, default=DEFAULT_TEXTURE)
    parser.add_argument("--preset", default="fast")
    parser.add_argument("--views", type=int, help="automatic views (default: the preset's)")
    parser.add_argument("--weights", type=Path, default=SHARED / "weights")
    parser.add_argument(
        "--set",
        dest="overrides",
        nargs="*",
        default=[],
        metavar="KEY=VALUE",
        help="TransferConfig settings over the preset",
    )
    parser.add_argument("--profile", action="store_true", help="split the time by component (cProfile)")
    parser.add_argument("--tile", type=int, default=1, help="K copies of the scene side by side (a larger capture)")
    parser.add_argument("--warm-bank", action="store_true", help="use the user's bank cache (not end to end)")
    parser.add_argument("--json", type=Path, help="default bench/out/transfer_<preset>.json")
    parser.add_argument("--backends", help="comma-separated rasterizer backends to run side by side (e.g. cpu,numba)")
    parser.add_argument("--rounds", type=int, default=1, help="with --backends: rounds of one run per backend")
    args = parser.parse_args()
    OUT.mkdir(parents=True, exist_ok=True)
    overrides = parse_overrides(args.overrides)
    if args.backends:
        records = compare_backends(args, overrides, args.backends.split(","))
        path = args.json or OUT / f"transfer_{args.preset}_backends.json"
        path.write_text(json.dumps(records, indent=1))
        print(f"records: {path}")
        return
    with tempfile.TemporaryDirectory() as fresh:
        record = run(args, overrides, None if args.warm_bank else fresh)
    print_record(record)
    path = args.json or OUT / f"transfer_{args.preset}.json"
    path.write_text(json.dumps(record, indent=1))
    print(f"record: {path}")


def compare_backends(args: argparse.Namespace, overrides: dict[str, Any], backends: list[str]) -> list[dict[str, Any]]:
    """``args.rounds`` rounds of one transfer per backend, interleaved in this process; prints every record,
    then the backends side by side (peak RSS is the process's so far: only the first run's is its own)."""
    records = []
    for round_ in range(args.rounds):
        for backend in backends:
            with tempfile.TemporaryDirectory() as fresh:
                record = run(args, {**overrides, "backend": backend}, None if args.warm_bank else fresh)
            record["round"] = round_
            print_record(record)
            records.append(record)
    first = {r["round"]: r["seconds"] for r in records if r["overrides"]["backend"] == backends[0]}
    print(f"\n{'backend':<8} {'total s (per round)':<24} {'stylise s':<18} {'ratio to ' + backends[0]:<14} peak MiB")
    for backend in backends:
        mine = [r for r in records if r["overrides"]["backend"] == backend]
        ratio = statistics.median(r["seconds"] / first[r["round"]] for r in mine)
        totals = ", ".join(f"{r['seconds']:.1f}" for r in mine)
        stylise = ", ".join(f"{r['stage_seconds'].get('stylise', 0.0):.1f}" for r in mine)
        peak = max(r["peak"]["rss_peak_mib"] for r in mine)
        print(f"{backend:<8} {totals:<24} {stylise:<18} {ratio:<14.2f} {peak:.0f}")
    return records


if __name__ == "__main__":
    main()
