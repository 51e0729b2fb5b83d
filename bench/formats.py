"""Benchmark reading and importing every splat format at 1M splats: the numpy reader and Blender's whole import.

For each format a random scene (``--splats``, SH degree ``--degree``; .splat holds degree 0 only) is written
by our writer (SOG by splat-transform, the only SOG writer here, at SH degree ``--sog-degree``: its k-means of
higher bands takes tens of minutes on 2 cores at 1M splats), then timed: ``read_splats`` (the
numpy reader Blender's import uses, with SOG's WebP images decoded by OpenCV here) and the whole
``gt2gs.import_ply`` operator in Blender (bpy; SOG decoded by Blender). Error columns measure what the
format kept against the source (max position error relative to the scene's extent, mean colour error).
Times are the best of ``--repeats``. Target: 1M splats import in <= 3 s per format.

Prints a table and writes bench/out/formats.json.
Run: .venv/bin/python bench/formats.py [--splats 1000000] [--degree 3] [--repeats 2]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import bpy
from common import random_scene

import gt2gs_blender
from gt2gs_blender.core.scene.codec import as_arrays, colour_from_dc
from gt2gs_blender.core.scene.files import FORMATS, PLY, SOG, read_splats, write_splats
from gt2gs_blender.core.scene.ply_write import write_ply

SPLAT_TRANSFORM = ROOT / "node_modules" / ".bin" / "splat-transform"
TARGET_S = 3.0


def best(fn, repeats: int) -> float:
    """The fastest of ``repeats`` runs of ``fn``, each on Blender's fresh factory settings."""
    times = []
    for _ in range(repeats):
        bpy.ops.wm.read_factory_settings(use_empty=True)
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times)


def write(fmt: str, source: Path, scene, folder: Path) -> Path:
    """The scene in ``fmt``: our writer, or splat-transform for SOG (from ``source``)."""
    path = folder / f"scene{FORMATS[fmt].extensions[0]}"
    if fmt == SOG:
        subprocess.run(
            [str(SPLAT_TRANSFORM), "-w", "-g", "cpu", str(source), str(path)], check=True, capture_output=True
        )
    elif fmt != PLY:
        write_splats(path, scene, fmt)
    else:
        path = source
    return path


def errors(source, read) -> tuple[float, float]:
    """Max position error over the scene's extent, and mean absolute colour error (0..1)."""
    extent = float(np.ptp(source.means, axis=0).max())
    position = float(np.abs(np.sort(read.means, axis=0) - np.sort(source.means, axis=0)).max()) / extent
    colour = float(np.abs(np.sort(colour_from_dc(read.sh_dc), 0) - np.sort(colour_from_dc(source.sh_dc), 0)).mean())
    return position, colour


def measure(fmt: str, source: Path, scene, folder: Path, repeats: int) -> dict:
    """Timings and errors of one format."""
    path = write(fmt, source, scene, folder)
    scene = read_splats(source) if fmt == SOG else scene
    read = read_splats(path)
    position, colour = errors(scene, read)
    return {
        "format": fmt,
        "file_mib": path.stat().st_size / 2**20,
        "read_splats_s": best(lambda: read_splats(path), repeats),
        "import_operator_s": best(lambda: bpy.ops.gt2gs.import_ply(filepath=str(path)), repeats),
        "max_position_error": position,
        "mean_colour_error": colour,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--splats", type=int, default=1_000_000)
    parser.add_argument("--degree", type=int, default=3)
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--sog-degree", type=int, default=0)
    parser.add_argument("--formats", nargs="+", default=list(FORMATS))
    args = parser.parse_args()
    out_dir = ROOT / "bench" / "out"
    out_dir.mkdir(parents=True, exist_ok=True)
    scene = as_arrays(random_scene(args.splats, args.degree))
    gt2gs_blender.register()
    try:
        with tempfile.TemporaryDirectory() as tmp:
            source, sog_source = Path(tmp) / "source.ply", Path(tmp) / "sog_source.ply"
            write_ply(source, scene)
            write_ply(sog_source, as_arrays(random_scene(args.splats, args.sog_degree)))
            rows = [
                measure(fmt, sog_source if fmt == SOG else source, scene, Path(tmp), args.repeats)
                for fmt in args.formats
            ]
    finally:
        gt2gs_blender.unregister()
    print(f"{args.splats:,} splats, SH degree {args.degree} (.splat: 0, SOG: {args.sog_degree})")
    print(f"{'format':>16}{'MiB':>8}{'read s':>9}{'import s':>10}{'pos err':>10}{'colour err':>12}")
    for r in rows:
        print(
            f"{r['format']:>16}{r['file_mib']:>8.1f}{r['read_splats_s']:>9.2f}{r['import_operator_s']:>10.2f}"
            f"{r['max_position_error']:>10.1e}{r['mean_colour_error']:>12.1e}"
        )
    result = {
        "benchmark": "formats",
        "splats": args.splats,
        "sh_degree": args.degree,
        "sog_sh_degree": args.sog_degree,
        "blender": bpy.app.version_string,
        "python": platform.python_version(),
        "machine": platform.machine(),
        "cpus": os.cpu_count(),
        "repeats": args.repeats,
        "target_import_s": TARGET_S,
        "rows": rows,
    }
    (out_dir / "formats.json").write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {out_dir / 'formats.json'}")


if __name__ == "__main__":
    main()
