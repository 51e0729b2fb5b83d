"""Wall time against quality error over presets and skips on the shared donut (the Pareto picture).

``python bench/tradeoff.py [--variants fast preview ...] [--reference-preset balanced|paper-360|...]
[--reference FILE.json]`` runs each variant (a preset plus TransferConfig overrides) on the donut with
the herringbone-wood photo, one after the other in this process, and compares its quality with the
reference run, ``--reference-preset`` with every skip off (default ``balanced``, about 15 min on 2
cores; ``paper-360``, the paper's schedule, is the reference to take on a GPU, hours on a CPU); its
record is reused from ``--reference`` when that file exists when the variants are done, else it runs
then and is written there, and it is plotted too. Quality error = how far texture match and
SSIM fall short of the reference, in percent (negative = better than the reference). Prints a
table, writes bench/out/tradeoff.json and bench/out/tradeoff.png (time vs error, Pareto front).
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

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from gt2gs_blender.core.scene.ply import read_ply
from gt2gs_blender.core.transfer.pipeline import transfer
from gt2gs_blender.core.transfer.presets import PRESETS, preset

SHARED = ROOT.parent / "shared"
OUT = ROOT / "bench" / "out"
SCENE = SHARED / "data" / "scenes" / "donut" / "point_cloud.ply"
TEXTURE = SHARED / "data" / "textures" / "herringbone_wood.jpg"
NO_SKIPS: dict[str, Any] = {"skip_hidden": False, "plateau_window": 0, "match_channels": 0}
VARIANTS: dict[str, tuple[str, dict[str, Any]]] = {
    "preview": ("preview", {}),
    "fast": ("fast", {}),
    "fast, no hidden skip": ("fast", {"skip_hidden": False}),
    "fast, no plateau stop": ("fast", {"plateau_window": 0}),
    "fast, hidden <= 1 px": ("fast", {"hidden_threshold": 1.0}),
    "fast, 100 steps": ("fast", {"stylise_steps": 100, "correct_steps": 50}),
    "fast, 200 steps, 36 angles": ("fast", {"stylise_steps": 200, "correct_steps": 100, "n_angles": 36}),
    "fast, 36 angles": ("fast", {"n_angles": 36}),
    "balanced": ("balanced", {}),
}
DEFAULT_VARIANTS = ("preview", "fast, 200 steps, 36 angles", "fast", "fast, no hidden skip", "fast, hidden <= 1 px")
METRICS = ("texture_match", "ssim", "lt_rmse")


def run(preset_name: str, overrides: dict[str, Any], cache_dir: str) -> dict[str, Any]:
    """One end-to-end transfer (the bank built into ``cache_dir``); its times and metrics."""
    config = preset(preset_name, weights_path=str(SHARED / "weights"), cache_dir=cache_dir, evaluate=True, **overrides)
    scene = read_ply(SCENE)
    load = os.getloadavg()
    start = time.perf_counter()
    report = transfer(scene, str(TEXTURE), None, config).report
    return {
        "preset": preset_name,
        "overrides": overrides,
        "seconds": time.perf_counter() - start,
        "stage_seconds": report["stage_seconds"],
        "metrics": report["metrics"],
        "skips": report["skips"],
        "n_gaussians": report["n_gaussians"],
        "load": load,
        "load_after": os.getloadavg(),
    }


def shortfall(record: dict[str, Any], reference: dict[str, Any]) -> dict[str, float]:
    """Percent by which texture match (lower is better) and SSIM (higher is better) fall short of
    the reference, and their maximum (the quality error plotted)."""
    m, r = record["metrics"], reference["metrics"]
    texture = 100.0 * (m["texture_match"] - r["texture_match"]) / r["texture_match"]
    ssim = 100.0 * (r["ssim"] - m["ssim"]) / r["ssim"]
    return {"texture_match_pct": texture, "ssim_pct": ssim, "error_pct": max(texture, ssim)}


def pareto(points: list[tuple[float, float]]) -> list[int]:
    """Indices of the points no other point beats in both time and error, by time."""
    order = sorted(range(len(points)), key=lambda i: points[i])
    front, best = [], float("inf")
    for i in order:
        if points[i][1] < best:
            front.append(i)
            best = points[i][1]
    return front


def plot(records: list[dict[str, Any]], path: Path, reference: str) -> None:
    """Wall time (log) against quality error, variants labelled, Pareto front drawn, 10 % line."""
    fig, ax = plt.subplots(figsize=(6.4, 3.6), dpi=100)
    points = [(r["seconds"], r["error_pct"]) for r in records]
    front = pareto(points)
    ax.plot(
        [points[i][0] for i in front], [points[i][1] for i in front], "-", color="0.7", zorder=1, label="Pareto front"
    )
    for i, (r, (x, y)) in enumerate(zip(records, points)):
        ax.scatter([x], [y], s=28, zorder=2, color="C3" if r["name"] == "fast" else "C0")
        ax.annotate(r["name"], (x, y), textcoords="offset points", xytext=(-20, 8 + 12 * (i % 3)), fontsize=7)
    ax.axhline(10.0, color="C2", linestyle=":", linewidth=1, label=f"10 % of {reference}")
    ax.set_xscale("log")
    ax.set_xlabel("wall time, end to end (s, 2 shared CPU cores)")
    ax.set_ylabel(f"quality shortfall vs {reference} (%)\nmax of texture match, SSIM")
    ax.set_title("GT²-GS on the donut (45.6k Gaussians), herringbone wood", fontsize=9)
    ax.set_ylim(-5, max(y for _, y in points) + 15)
    ax.legend(fontsize=7, loc="upper right")
    ax.grid(True, which="both", linewidth=0.3)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--variants", nargs="+", choices=tuple(VARIANTS), default=list(DEFAULT_VARIANTS))
    parser.add_argument(
        "--reference-preset",
        choices=tuple(PRESETS),
        default="balanced",
        help="the quality reference, run with every skip off (default: balanced)",
    )
    parser.add_argument(
        "--reference", type=Path, help="its record (default bench/out/transfer_<preset>_ref.json; run when missing)"
    )
    parser.add_argument("--json", type=Path, default=OUT / "tradeoff.json")
    parser.add_argument("--png", type=Path, default=OUT / "tradeoff.png")
    args = parser.parse_args()
    args.reference = args.reference or OUT / f"transfer_{args.reference_preset}_ref.json"
    OUT.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as cache:
        records = []
        for name in args.variants:
            with tempfile.TemporaryDirectory(dir=cache) as fresh:  # every variant builds its own bank
                records.append({"name": name, **run(*VARIANTS[name], fresh)})
            print(f"{name}: {records[-1]['seconds']:.1f} s", flush=True)
        if args.reference.is_file():
            reference = json.loads(args.reference.read_text())
        else:
            reference = run(args.reference_preset, NO_SKIPS, cache)
            args.reference.write_text(json.dumps(reference, indent=1))
    records.append({"name": f"{args.reference_preset}, no skips (reference)", **reference})
    print(
        f"{'variant':<32} {'s':>7} {'load':>5} "
        + " ".join(f"{m:>13}" for m in METRICS)
        + f" {'tm short %':>10} {'ssim short %':>12} {'hidden':>7}"
    )
    for record in records:
        record.update(shortfall(record, reference))
        load = record.get("load") or record.get("load_before")
        cells = " ".join(f"{record['metrics'][m]:>13.4f}" for m in METRICS)
        print(
            f"{record['name']:<32} {record['seconds']:>7.1f} {load[0]:>5.1f} {cells} "
            f"{record['texture_match_pct']:>10.1f} {record['ssim_pct']:>12.1f} "
            f"{(record.get('skips') or {}).get('hidden')!s:>7}"
        )
    args.json.write_text(json.dumps({"reference": reference, "records": records}, indent=1))
    plot(records, args.png, args.reference_preset)
    print(f"records: {args.json}\nplot: {args.png}")


if __name__ == "__main__":
    main()
