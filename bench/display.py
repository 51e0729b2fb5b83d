"""The Gaussian display's cost: set-up (modifier + first evaluation) at 45k and 1M splats, and render times.

    .venv/bin/python bench/display.py [--skip-cycles]

Prints a table and writes bench/out/display.json. Renders are the shared donut at 256 px, 32 samples, from
its first generated view, after gt2gs.setup_scene (EEVEE's first render includes its shader compilation).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import bpy

import gt2gs_blender
from gt2gs_blender.blender import display, splats, views
from gt2gs_blender.core.scene.arrays import SplatArrays

DONUT = ROOT.parent / "shared" / "data" / "scenes" / "donut" / "point_cloud.ply"
OUT = ROOT / "bench" / "out" / "display.json"


def random_arrays(n: int, seed: int = 0) -> SplatArrays:
    """``n`` random degree-0 splats in a unit cube."""
    rng = np.random.default_rng(seed)
    f32 = np.float32
    return SplatArrays(
        means=rng.uniform(-1, 1, (n, 3)).astype(f32),
        quats=rng.normal(size=(n, 4)).astype(f32),
        log_scales=(rng.normal(size=(n, 3)) - 5).astype(f32),
        opacity_logits=rng.normal(size=n).astype(f32),
        sh_dc=rng.normal(size=(n, 3)).astype(f32),
        sh_rest=np.zeros((n, 0, 3), f32),
        extras={},
    )


def setup_times(n: int) -> dict:
    """Seconds to add the modifier and to evaluate it (the quads) for ``n`` splats."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    camera = bpy.data.objects.new("cam", bpy.data.cameras.new("cam"))
    scene.collection.objects.link(camera)
    scene.camera, camera.location = camera, (0.0, -4.0, 0.0)
    camera.rotation_euler = (np.pi / 2, 0.0, 0.0)
    obj = splats.scene_to_object(random_arrays(n), "bench", scene.collection, with_display=False)
    start = time.perf_counter()
    display.apply_display(obj)
    added = time.perf_counter() - start
    start = time.perf_counter()
    evaluated = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
    geometry = evaluated.evaluated_geometry()  # keep it referenced while its mesh is read
    faces = len(geometry.mesh.polygons)
    return {"splats": n, "add_s": added, "evaluate_s": time.perf_counter() - start, "quads": faces}


def render_times(engines: list[str]) -> dict:
    """Seconds per 256 px render of the donut from its first generated view (the display test's view 0), per
    engine (two renders: the first, then a warm one)."""
    from gt2gs_blender.core.cameras.generate import auto_views
    from gt2gs_blender.core.scene.files import read_scene

    bpy.ops.wm.read_factory_settings(use_empty=True)
    assert bpy.ops.gt2gs.import_ply(filepath=str(DONUT), setup_scene=True) == {"FINISHED"}
    scene = bpy.context.scene
    scene.render.resolution_x = scene.render.resolution_y = 256
    scene.eevee.taa_render_samples = scene.cycles.samples = 32
    scene.cycles.device = "CPU"
    view = auto_views(read_scene(DONUT), 4, width=256, height=256)[0]
    scene.camera = views.add_camera(view, scene.collection)
    times = {}
    for engine in engines:
        scene.render.engine = engine
        runs = []
        for _ in range(2):
            start = time.perf_counter()
            bpy.ops.render.render()
            runs.append(time.perf_counter() - start)
        times[engine] = {"first_s": runs[0], "warm_s": runs[1]}
    return times


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--skip-cycles", action="store_true")
    args = parser.parse_args()
    gt2gs_blender.register()
    setups = [setup_times(n) for n in (45_624, 1_000_000)]
    engines = ["BLENDER_EEVEE"] + ([] if args.skip_cycles else ["CYCLES"])
    renders = render_times(engines) if DONUT.is_file() else {}
    print(f"{'splats':>10} {'add modifier (s)':>17} {'evaluate (s)':>13} {'quads':>10}")
    for row in setups:
        print(f"{row['splats']:>10,} {row['add_s']:>17.3f} {row['evaluate_s']:>13.3f} {row['quads']:>10,}")
    for engine, row in renders.items():
        print(f"{engine:>14} 256 px, 32 samples: first {row['first_s']:.1f} s, warm {row['warm_s']:.1f} s")
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(json.dumps({"setup": setups, "render": renders}, indent=2))
    print("wrote", OUT)


if __name__ == "__main__":
    main()
