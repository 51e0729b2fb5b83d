"""Benchmark importing and exporting Gaussian splat PLYs in Blender (bpy module), SH degree 3 + normals.

For each size: the whole ``gt2gs.import_ply`` operator (file -> point-cloud object with every attribute,
colour, radius and material), its two parts (core ``read_ply_arrays``, the numpy reader the operator uses;
the ``SplatArrays`` -> object conversion), the whole ``gt2gs.export_ply`` operator, and whether the exported
file equals the source byte for byte. Times are the best of ``--repeats`` runs, each on fresh factory
settings; the engine's imports (torch) are warmed up first, as they are in a Blender session after the first
import. Target: 1M splats import in ≤ 3 s.

Prints a table and writes bench/out/blender_import.json.
Run: .venv/bin/python bench/blender_import.py [--sizes 100000 1000000] [--repeats 3]
"""

from __future__ import annotations

import argparse
import filecmp
import json
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import bpy
import torch
from common import random_scene

import gt2gs_blender
from gt2gs_blender.blender import splats
from gt2gs_blender.core.scene.ply import read_ply, read_ply_arrays
from gt2gs_blender.core.scene.ply_write import write_ply


def timed(fn) -> tuple[float, object]:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    start = time.perf_counter()
    result = fn()
    return time.perf_counter() - start, result


def best(fn, repeats: int) -> float:
    return min(timed(fn)[0] for _ in range(repeats))


def measure(n: int, degree: int, repeats: int, tmp: str) -> dict:
    src = os.path.join(tmp, f"splats_{n}.ply")
    dst = os.path.join(tmp, f"export_{n}.ply")
    write_ply(src, random_scene(n, degree))
    read_ply(src)  # warm the page cache and the engine's imports
    scene = read_ply_arrays(src)

    def export() -> float:
        bpy.ops.gt2gs.import_ply(filepath=src)
        start = time.perf_counter()
        bpy.ops.gt2gs.export_ply(filepath=dst)
        return time.perf_counter() - start

    return {
        "splats": n,
        "sh_degree": degree,
        "ply_properties": 3 * (degree + 1) ** 2 + 8 + 3,
        "file_mib": os.path.getsize(src) / 2**20,
        "read_ply_arrays_s": best(lambda: read_ply_arrays(src), repeats),
        "scene_to_object_s": best(
            lambda: splats.scene_to_object(scene, "bench", bpy.context.scene.collection), repeats
        ),
        "import_operator_s": best(lambda: bpy.ops.gt2gs.import_ply(filepath=src), repeats),
        "export_operator_s": min(timed(export)[1] for _ in range(repeats)),
        "byte_exact_round_trip": filecmp.cmp(src, dst, shallow=False),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[100_000, 1_000_000])
    parser.add_argument("--degree", type=int, default=3)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    out_dir = ROOT / "bench" / "out"
    out_dir.mkdir(parents=True, exist_ok=True)
    gt2gs_blender.register()
    try:
        with tempfile.TemporaryDirectory() as tmp:
            rows = [measure(n, args.degree, args.repeats, tmp) for n in args.sizes]
    finally:
        gt2gs_blender.unregister()

    print(
        f"{'splats':>10}{'MiB':>8}{'read s':>12}{'to object s':>13}{'import op s':>13}{'export op s':>13}  byte-exact"
    )
    for r in rows:
        print(
            f"{r['splats']:>10,}{r['file_mib']:>8.1f}{r['read_ply_arrays_s']:>12.3f}{r['scene_to_object_s']:>13.3f}"
            f"{r['import_operator_s']:>13.3f}{r['export_operator_s']:>13.3f}  {r['byte_exact_round_trip']}"
        )
    result = {
        "benchmark": "blender_import",
        "blender": bpy.app.version_string,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "torch": torch.__version__,
        "machine": platform.machine(),
        "cpus": os.cpu_count(),
        "repeats": args.repeats,
        "target_1m_import_s": 3.0,
        "rows": rows,
    }
    (out_dir / "blender_import.json").write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {out_dir / 'blender_import.json'}")


if __name__ == "__main__":
    main()
