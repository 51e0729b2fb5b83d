"""README's Blender picture: the imported donut and ``make demo``'s result, each rendered by the project's
rasterizer and by Blender's EEVEE from the donut's first generated view, with the object SSIM of each pair.

    .venv/bin/python bench/blender_pictures.py [--result out/demo/stylised.ply]

Writes docs/blender_eevee.jpg (top: the import, bottom: the result; left: rasterizer, right: EEVEE) and prints
the SSIMs. EEVEE renders after gt2gs.setup_scene, 256 px, 32 samples, white world, Blender's default filter.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import cv2
import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import bpy

import gt2gs_blender
from gt2gs_blender.blender import views
from gt2gs_blender.core.cameras.generate import auto_views
from gt2gs_blender.core.render import render
from gt2gs_blender.core.scene.files import read_scene
from gt2gs_blender.core.transfer.metrics import masked_ssim

DONUT = ROOT.parent / "shared" / "data" / "scenes" / "donut" / "point_cloud.ply"
RESULT = ROOT / "out" / "demo" / "stylised.ply"
OUT = ROOT / "docs" / "blender_eevee.jpg"
SIZE = 256
SAMPLES = 32


def rasterized(path: Path, camera) -> tuple[np.ndarray, np.ndarray]:
    """(H,W,3) float colours over white and (H,W) alpha of ``path`` by the project's rasterizer."""
    with torch.no_grad():
        out = render(read_scene(path), [camera], background=(1.0, 1.0, 1.0))
    return out.colors[0].clamp(0.0, 1.0).numpy(), out.alphas[0].numpy()


def eevee(path: Path, camera, folder: Path) -> np.ndarray:
    """(H,W,3) float colours of ``path`` imported into a fresh scene and rendered by EEVEE from ``camera``."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    assert bpy.ops.gt2gs.import_ply(filepath=str(path), setup_scene=True) == {"FINISHED"}
    scene = bpy.context.scene
    scene.render.engine = "BLENDER_EEVEE"
    scene.render.resolution_x = scene.render.resolution_y = SIZE
    scene.render.resolution_percentage = 100
    scene.eevee.taa_render_samples = SAMPLES
    world = bpy.data.worlds.new("white")
    background = next(n for n in world.node_tree.nodes if n.bl_idname == "ShaderNodeBackground")
    background.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    scene.world = world
    scene.camera = views.add_camera(camera, scene.collection)
    scene.render.filepath = str(folder / f"{path.stem}.png")
    bpy.ops.render.render(write_still=True)
    image = cv2.imread(scene.render.filepath, cv2.IMREAD_COLOR)
    return cv2.cvtColor(image, cv2.COLOR_BGR2RGB).astype(np.float32) / 255.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--result", type=Path, default=RESULT, help="the transfer result to show (make demo's)")
    args = parser.parse_args()
    if not args.result.is_file():
        raise SystemExit(f"{args.result}: no transfer result; run `make demo` first or pass --result")
    gt2gs_blender.register()
    camera = auto_views(read_scene(DONUT), 4, width=SIZE, height=SIZE)[0]
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        for label, path in (("import", DONUT), ("result", args.result)):
            reference, alpha = rasterized(path, camera)
            blender = eevee(path, camera, Path(folder))
            score = masked_ssim(torch.from_numpy(blender), torch.from_numpy(reference), torch.from_numpy(alpha > 0.5))
            print(f"{label:>7}: object SSIM EEVEE vs rasterizer {score:.3f}")
            rows.append(np.concatenate([reference, blender], axis=1))
    picture = (np.concatenate(rows, axis=0) * 255.0 + 0.5).astype(np.uint8)
    cv2.imwrite(str(OUT), cv2.cvtColor(picture, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, 85])
    print("wrote", OUT)


if __name__ == "__main__":
    main()
