"""A real Blender window, as an artist uses it: run by ``tests/gui/run.sh`` as ``blender --python smoke.py -- OUT``.

With the built extension installed and enabled, it imports the shared donut, opens the GT² tab of the 3D View's
sidebar, screenshots the idle panel, runs a ``preview`` transfer through the modal operator (the worker on
GT2GS_WORKER_PYTHON) and screenshots the finished run, each step from a timer so the window draws between them.
``OUT/smoke.json`` says what it found; the shell script checks it and the console log.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
import traceback
from pathlib import Path

import bpy

OUT = Path(sys.argv[sys.argv.index("--") + 1])
DONUT = Path(__file__).resolve().parents[3] / "shared" / "data" / "scenes" / "donut" / "point_cloud.ply"
TEXTURE = DONUT.parents[2] / "textures" / "herringbone_wood.jpg"
TIMEOUT_S = 1200.0
SHADERS_S = 30.0
"""Time for EEVEE to compile the splat material's shaders (software OpenGL under Xvfb) before a screenshot."""
found: dict = {"steps": []}


def package():
    """The installed extension's package (``bl_ext.<repository>.gt2gs_blender``)."""
    name = next(n for n in sys.modules if n.startswith("bl_ext.") and n.endswith(".gt2gs_blender"))
    return sys.modules[name]


def view3d(kind: str = "UI"):
    """(window, area, region of ``kind``) of the 3D View."""
    window = bpy.context.window_manager.windows[0]
    area = next(a for a in window.screen.areas if a.type == "VIEW_3D")
    return window, area, next(r for r in area.regions if r.type == kind)


def screenshot(name: str) -> None:
    """The whole X screen, as the artist sees it (ImageMagick's import)."""
    path = OUT / f"{name}.png"
    subprocess.run(["import", "-window", "root", str(path)], check=True, timeout=60)
    found["steps"].append(f"screenshot {path.name}")


def finish(error: str | None = None) -> None:
    found["error"] = error
    (OUT / "smoke.json").write_text(json.dumps(found, indent=1))
    bpy.ops.wm.quit_blender()


def step(fn):
    """A timer callback that records a failure and quits instead of leaving the window open."""

    def run():
        try:
            return fn()
        except Exception:
            traceback.print_exc()
            finish(traceback.format_exc().strip().splitlines()[-1])
            return None

    return run


@step
def start():
    found["blender"] = bpy.app.version_string
    found["python"] = sys.version.split()[0]
    found["extension"] = package().__name__
    window, area, region = view3d("WINDOW")
    with bpy.context.temp_override(window=window, area=area, region=region):
        bpy.ops.gt2gs.import_ply(filepath=str(DONUT))
        obj = bpy.context.active_object
        found["imported"] = obj.name
        settings = bpy.context.scene.gt2gs
        settings.texture_path = str(TEXTURE)
        settings.preset = "preview"
        area.spaces.active.show_region_ui = True
        area.spaces.active.shading.type = "MATERIAL"
        bpy.ops.view3d.view_selected()
    bpy.app.timers.register(step(open_tab), first_interval=2.0)


@step
def open_tab():
    _, _, region = view3d()
    region.active_panel_category = "GT²"
    found["tab"] = region.active_panel_category
    bpy.app.timers.register(step(idle_shot), first_interval=SHADERS_S)


@step
def idle_shot():
    screenshot("gui_idle_panel")
    window, area, region = view3d()
    with bpy.context.temp_override(window=window, area=area, region=region):
        found["transfer_started"] = sorted(bpy.ops.gt2gs.transfer_texture("INVOKE_DEFAULT"))
    found["started_at"] = time.monotonic()
    bpy.app.timers.register(step(wait_for_run), first_interval=2.0)


@step
def wait_for_run():
    transfer_run = sys.modules[f"{package().__name__}.blender.transfer_run"]
    outcome = transfer_run.OUTCOMES.get("transfer")
    if outcome is None and time.monotonic() - found["started_at"] < TIMEOUT_S:
        return 2.0
    if outcome is None:
        finish(f"no outcome after {TIMEOUT_S:.0f} s")
        return None
    found["outcome"] = {"state": outcome.state, "message": outcome.message, "result": outcome.result}
    found["result_exists"] = outcome.result in bpy.data.objects
    found["source_hidden"] = bpy.data.objects[found["imported"]].hide_get()
    bpy.app.timers.register(step(done_shot), first_interval=SHADERS_S)
    return None


@step
def done_shot():
    screenshot("gui_finished_run")
    finish()


bpy.app.timers.register(step(start), first_interval=3.0)
