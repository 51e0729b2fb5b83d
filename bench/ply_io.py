"""Benchmark PLY reading and writing: 1M Gaussians, SH degree 3, every format.

Prints a table (ms, best of ``--repeats``) and writes bench/out/ply_io.json. ASCII uses fewer
Gaussians by default (``--ascii-n``) because text formatting is far slower than binary I/O.
Run: python bench/ply_io.py [--n 1000000] [--ascii-n 100000] [--repeats 3]
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from common import random_scene

from gt2gs_blender.core.scene.ply import read_ply
from gt2gs_blender.core.scene.ply_write import write_ply


def best_ms(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append((time.perf_counter() - start) * 1e3)
    return min(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=1_000_000)
    parser.add_argument("--ascii-n", type=int, default=100_000)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    out_dir = Path(__file__).resolve().parent / "out"
    out_dir.mkdir(parents=True, exist_ok=True)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for fmt, n in (("binary_little_endian", args.n), ("binary_big_endian", args.n), ("ascii", args.ascii_n)):
            scene = random_scene(n)
            path = Path(tmp) / f"{fmt}.ply"
            write_ms = best_ms(lambda path=path, scene=scene, fmt=fmt: write_ply(path, scene, fmt=fmt), args.repeats)
            read_ms = best_ms(lambda path=path: read_ply(path), args.repeats)
            loaded = read_ply(path)
            exact = all(torch.equal(a, b) for a, b in zip(scene.tensors().values(), loaded.tensors().values()))
            rows.append(
                {
                    "format": fmt,
                    "gaussians": n,
                    "sh_degree": 3,
                    "mib": path.stat().st_size / 2**20,
                    "write_ms": write_ms,
                    "read_ms": read_ms,
                    "exact_round_trip": exact,
                }
            )
    print(f"{'format':<22}{'gaussians':>11}{'MiB':>9}{'write ms':>11}{'read ms':>10}  exact")
    for r in rows:
        print(
            f"{r['format']:<22}{r['gaussians']:>11,}{r['mib']:>9.1f}{r['write_ms']:>11.1f}"
            f"{r['read_ms']:>10.1f}  {r['exact_round_trip']}"
        )
    result = {
        "benchmark": "ply_io",
        "python": platform.python_version(),
        "numpy": np.__version__,
        "torch": torch.__version__,
        "machine": platform.machine(),
        "repeats": args.repeats,
        "rows": rows,
    }
    (out_dir / "ply_io.json").write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {out_dir / 'ply_io.json'}")


if __name__ == "__main__":
    main()
