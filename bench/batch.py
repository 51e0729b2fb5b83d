"""Batch throughput (jobs per hour) on this machine: a shell loop of ``transfer`` commands vs the ``batch`` command
on a local Dask cluster of 1 worker x all cores and of 2 workers x half the cores each.

``python bench/batch.py [--jobs 4] [--preset preview] [--rounds 2]`` runs the same jobs (the shared donut x the
first ``--jobs`` shared textures) each way, interleaved round by round in this process, every batch into a fresh
folder; keeps the fastest round of each (the machine is shared: the minimum is the estimate). A batch's time is
counted from its first job's start to its last job's end (jobs per hour at steady state), and its start-up (the
local cluster's workers importing torch) is shown apart. Prints the table with the load average and the
cluster estimate (this machine's rate times the machines: Dask's own cost per job is milliseconds against jobs of
seconds to hours, so the bound is the shared storage, not the scheduler; an estimate, not measured here), and
writes bench/out/batch.json.
"""

from __future__ import annotations

import argparse
import io
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from gt2gs_blender.app.batch.cluster import run_batch

SHARED = ROOT.parent / "shared" / "data"
TEXTURES = ("brick_wall", "swirls", "green_cells", "woven_straw", "tree_bark", "honeycomb", "cracked_earth")


class Clock(io.StringIO):
    """The batch's progress stream, with the time each start or end line came."""

    def __init__(self) -> None:
        super().__init__()
        self.times: list[float] = []

    def write(self, text: str) -> int:
        if text.startswith(("start ", "done ", "failed ")):
            self.times.append(time.perf_counter())
        return super().write(text)


def shell_loop(jobs: list[tuple[Path, Path]], preset: str, threads: int, folder: Path) -> dict:
    """One ``transfer`` command after another (what a shell loop does): total seconds."""
    started = time.perf_counter()
    for i, (scene, texture) in enumerate(jobs):
        command = [sys.executable, "-m", "gt2gs_blender", "transfer", str(scene), str(texture)]
        command += ["-o", str(folder / f"{i}.ply"), "--preset", preset, "--threads", str(threads)]
        command += ["--strip", str(folder / f"{i}.png"), "--report", str(folder / f"{i}.json")]
        subprocess.run(command, check=True, capture_output=True, cwd=ROOT)
    seconds = time.perf_counter() - started
    return {"seconds": seconds, "startup": 0.0}


def batch(manifest: Path, workers: int, threads: int, folder: Path) -> dict:
    """The batch command's run on a local cluster: seconds from the first start to the last end, and before it."""
    clock = Clock()
    started = time.perf_counter()
    result = run_batch(manifest, folder, workers=workers, threads=threads, stream=clock)
    assert not result.failed, [row.error for row in result.failed]
    return {"seconds": clock.times[-1] - clock.times[0], "startup": clock.times[0] - started}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--jobs", type=int, default=4, help="jobs per run (the donut x this many textures)")
    parser.add_argument("--preset", default="preview")
    parser.add_argument("--rounds", type=int, default=2)
    args = parser.parse_args()
    cores = len(os.sched_getaffinity(0))
    scene = SHARED / "scenes" / "donut" / "point_cloud.ply"
    textures = [SHARED / "textures" / f"{name}.jpg" for name in TEXTURES[: args.jobs]]
    ways = {
        f"shell loop of transfer commands ({cores} threads)": lambda f, m: shell_loop(
            [(scene, t) for t in textures], args.preset, cores, f
        ),
        f"batch, 1 worker x {cores} threads": lambda f, m: batch(m, 1, cores, f),
        f"batch, 2 workers x {max(1, cores // 2)} threads": lambda f, m: batch(m, 2, max(1, cores // 2), f),
    }
    best: dict[str, dict] = {}
    with tempfile.TemporaryDirectory() as tmp:
        manifest = Path(tmp) / "jobs.csv"
        manifest.write_text("scene,texture,preset\n" + "".join(f"{scene},{t},{args.preset}\n" for t in textures))
        for r in range(args.rounds):
            for name, way in ways.items():
                folder = Path(tmp) / f"{r}-{len(best)}-{abs(hash(name))}"
                folder.mkdir()
                measured = way(folder, manifest)
                print(f"round {r + 1}: {name}: {measured['seconds']:.1f} s (+{measured['startup']:.1f} s start-up)")
                if name not in best or measured["seconds"] < best[name]["seconds"]:
                    best[name] = measured
    load = os.getloadavg()[0]
    print(f"\n{len(textures)} {args.preset} jobs on the donut, {cores} cores, load average {load:.1f} (shared machine)")
    print("| way | seconds | start-up s | jobs/hour |")
    print("|---|---|---|---|")
    rates = {}
    for name, measured in best.items():
        rates[name] = len(textures) * 3600 / measured["seconds"]
        print(f"| {name} | {measured['seconds']:.1f} | {measured['startup']:.1f} | {rates[name]:.0f} |")
    top = max(rates.values())
    print(f"\ncluster estimate (not measured): N machines like this one ~ N x {top:.0f} jobs/hour")
    out = ROOT / "bench" / "out"
    out.mkdir(parents=True, exist_ok=True)
    record = {"jobs": len(textures), "preset": args.preset, "cores": cores, "load": load, "best": best, "rates": rates}
    (out / "batch.json").write_text(json.dumps(record, indent=1))


if __name__ == "__main__":
    main()
