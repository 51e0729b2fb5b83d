"""The layout's prefilter pyramid: the periodic blur (``grain.periodic_blur``) against OpenCV's mirrored one it
replaced, per pyramid level, on a 1k and a 4k photo: time (best of 3) and how far the two differ away from the
photo's edges (the seam fix changes only the edges; the interior shows the two blurs are the same Gaussian).

    python bench/pyramid.py                 # 1024 and 4096 px
    python bench/pyramid.py --sizes 2048

Prints a table and writes bench/out/pyramid.json.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from gt2gs_blender.core.transfer.grain import periodic_blur
from gt2gs_blender.core.transfer.layout import PYRAMID_LEVELS

OUT = ROOT / "bench" / "out" / "pyramid.json"


def best_of(f: Callable[[], np.ndarray], repeats: int = 3) -> tuple[float, np.ndarray]:
    """The shortest of ``repeats`` timings of ``f`` and its result."""
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = f()
        times.append(time.perf_counter() - t0)
    return min(times), out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[1024, 4096])
    args = parser.parse_args()
    rows = []
    print(f"torch threads {torch.get_num_threads()}")
    print("size  level  sigma   mirrored s  periodic s  ratio  max diff inside")
    for size in args.sizes:
        photo = np.random.default_rng(0).random((size, size, 3), dtype=np.float32)
        for level in range(1, PYRAMID_LEVELS):
            sigma = 0.5 * 2.0**level
            mirrored_s, mirrored = best_of(lambda p=photo, s=sigma: cv2.GaussianBlur(p, (0, 0), s))
            periodic_s, periodic = best_of(lambda p=photo, s=sigma: periodic_blur(p, s))
            edge = min(math.ceil(4 * sigma) + 1, size // 2 - 1)
            inside = float(np.abs(mirrored - periodic)[edge:-edge, edge:-edge].max())
            rows.append(
                dict(
                    size=size,
                    level=level,
                    sigma=sigma,
                    mirrored_s=mirrored_s,
                    periodic_s=periodic_s,
                    ratio=periodic_s / mirrored_s,
                    max_diff_inside=inside,
                )
            )
            print(
                f"{size:5d} {level:5d} {sigma:6g} {mirrored_s:11.3f} {periodic_s:11.3f} "
                f"{periodic_s / mirrored_s:6.2f}  {inside:.1e}",
                flush=True,
            )
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(json.dumps({"torch_threads": torch.get_num_threads(), "rows": rows}, indent=1))
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
