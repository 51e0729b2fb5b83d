"""A close look at saved results: the original and each result from one held-out view, larger than the run's views.

``python bench/closeup.py SCENE RESULT.ply [RESULT.ply ...] [--view 0] [--size 1024] [--box X0,Y0,X1,Y1]
[--out PATH]`` renders ``SCENE`` (one of bench/recognise_scenes.py's) and the results (such as those
bench/recognise.py saves under bench/out/recognise/<tag>/<scene>/) from held-out view ``--view`` at longest side
``--size``, crops ``--box`` (fractions of the frame) from each and writes them side by side, original first, to
``--out`` (default bench/out/closeup/<scene>-v<view>.png). docs/quality_log.md's close-ups are made with it; for
example the robot's head: ``python bench/closeup.py playbot bench/out/recognise/s11-hue/playbot/woven_straw-fast-s0.ply
bench/out/recognise/s12-dense/playbot/woven_straw-fast-s0.ply --box 0.33,0.33,0.67,0.72``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))
sys.path.insert(0, str(ROOT))

from recognise_scenes import CAPTURE_SCALE, CAPTURES, SCENES, load_bench_scene

from gt2gs_blender.app.images import write_png
from gt2gs_blender.core.api import GaussianScene, read_scene, render

OUT = ROOT / "bench" / "out" / "closeup"


def crop(image: np.ndarray, box: tuple[float, float, float, float]) -> np.ndarray:
    """The part of ``image`` inside ``box`` (x0, y0, x1, y1 as fractions of its width and height)."""
    height, width = image.shape[:2]
    x0, y0, x1, y1 = box
    return image[int(y0 * height) : int(y1 * height), int(x0 * width) : int(x1 * width)]


@torch.no_grad()
def closeup(scene_name: str, results: list[Path], view: int, size: int, box: tuple[float, ...]) -> np.ndarray:
    """(H, W, 3) uint8: the original and each result from held-out ``view`` at longest side ``size``, cropped."""
    bench = load_bench_scene(scene_name, size // CAPTURE_SCALE if scene_name in CAPTURES else size)
    camera = bench.held_out[view]
    scenes: list[GaussianScene] = [bench.scene, *(read_scene(path) for path in results)]
    tiles = [
        crop(render(s, [camera], background=bench.background, render_depth=False).colors[0, ..., :3].numpy(), box)
        for s in scenes
    ]
    return (np.concatenate(tiles, axis=1).clip(0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scene", choices=SCENES)
    parser.add_argument("results", nargs="+", type=Path, metavar="RESULT.ply")
    parser.add_argument("--view", type=int, default=0, help="held-out view (0-3)")
    parser.add_argument("--size", type=int, default=1024, help="longest side of the render, px")
    parser.add_argument("--box", default="0,0,1,1", help="crop x0,y0,x1,y1 as fractions of the frame")
    parser.add_argument("--out", type=Path)
    args = parser.parse_args()
    box = tuple(float(v) for v in args.box.split(","))
    out = args.out or OUT / f"{args.scene}-v{args.view}.png"
    out.parent.mkdir(parents=True, exist_ok=True)
    write_png(out, closeup(args.scene, args.results, args.view, args.size, box))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
