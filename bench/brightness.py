"""How bright saved results come out: the mean luminance over the object's pixels in a scene's held-out views, beside
the original's and each texture photo's own.

``python bench/brightness.py SCENE TAG [TAG ...] [--textures NAME ...] [--preset fast] [--seed 0]`` reads the results
bench/recognise.py saved under bench/out/recognise/<TAG>/<SCENE>/<texture>-<preset>-s<seed>.ply, renders each from
the scene's held-out views at the bench's size, and averages the luminance (Rec. 709 weights, as the engine takes it)
of the pixels the original covers (alpha 0.9 and above). It prints a table and writes
bench/out/brightness/<SCENE>.json. docs/quality_log.md's *Keep Material* section is made with it: whether a result keeps
the capture's brightness or takes the photo's.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))
sys.path.insert(0, str(ROOT))

from recognise import texture_path
from recognise_scenes import SCENES, load_bench_scene

from gt2gs_blender.core.api import GaussianScene, read_scene, render
from gt2gs_blender.core.transfer.texture import load_texture
from gt2gs_blender.core.transfer.tone import luma

OUT = ROOT / "bench" / "out" / "brightness"
RESULTS = ROOT / "bench" / "out" / "recognise"
COVERED = 0.9
"""Pixels the original covers at least this much are the object's."""
TEXTURES = ("woven_straw", "honeycomb", "toy_bricks")


@torch.no_grad()
def mean_luminance(scene: GaussianScene, cameras: list, covered: list[torch.Tensor]) -> float:
    """The mean luminance of ``scene``'s colour (alpha divided out) over the ``covered`` pixels of each camera."""
    values = []
    for camera, mask in zip(cameras, covered):
        out = render(scene, [camera], render_depth=False)
        colour = out.colors[0][..., :3][mask] / out.alphas[0][mask].clamp_min(1e-6)[:, None]
        values.append(luma(colour.clamp(0.0, 1.0)))
    return float(torch.cat(values).mean())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scene", choices=SCENES)
    parser.add_argument("tags", nargs="+", metavar="TAG")
    parser.add_argument("--textures", nargs="+", default=list(TEXTURES), metavar="NAME")
    parser.add_argument("--preset", default="fast")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    bench = load_bench_scene(args.scene)  # held-out views at the size bench/recognise.py judges them
    cameras = list(bench.held_out)
    covered = [render(bench.scene, [c], render_depth=False).alphas[0] >= COVERED for c in cameras]
    original = mean_luminance(bench.scene, cameras, covered)
    table = {"original": original, "textures": {}}
    print(f"{args.scene}: original {original:.3f}")
    print(f"{'texture':17s} {'photo':>6s} " + " ".join(f"{tag:>18s}" for tag in args.tags))
    for texture in args.textures:
        photo = float(luma(torch.from_numpy(np.asarray(load_texture(texture_path(texture)))[..., :3])).mean())
        row = {"photo": photo}
        for tag in args.tags:
            saved = RESULTS / tag / args.scene / f"{texture}-{args.preset}-s{args.seed}.ply"
            row[tag] = mean_luminance(read_scene(saved), cameras, covered) if saved.exists() else None
        table["textures"][texture] = row
        cells = " ".join(f"{'-' if row[t] is None else format(row[t], '.3f'):>18s}" for t in args.tags)
        print(f"{texture:17s} {photo:6.3f} {cells}")
    OUT.mkdir(parents=True, exist_ok=True)
    out = OUT / f"{args.scene}.json"
    out.write_text(json.dumps({"args": vars(args), **table}, indent=2))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
