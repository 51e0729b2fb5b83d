"""The transfer from Blender: operators through bpy.ops, the worker/poll cycle of the modal operator
(driven by test ticks), cancel and crash, the panel's state function, preferences, views, batch script."""

from __future__ import annotations

import glob
import importlib.util
import json
import math
import os
import re
import resource
import signal
import sys
import tempfile
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

bpy = pytest.importorskip("bpy", exc_type=ModuleNotFoundError)

from gt2gs_blender.app import deps
from gt2gs_blender.app.images import write_png
from gt2gs_blender.blender import machine, splats, transfer_run, views
from gt2gs_blender.blender.job import CANCELLED, DONE, ERROR, IDLE, RUNNING, JobStatus, worker_python
from gt2gs_blender.blender.transfer_run import eta_text
from gt2gs_blender.core.errors import MEMORY_ADVICE
from gt2gs_blender.core.scene.ply_write import write_ply
from gt2gs_blender.panels.result import NO_RUN_TEXT, result_view
from gt2gs_blender.panels.transfer_panel import NO_WEIGHTS_WARNING, machine_warnings, transfer_view

from ..worker_tools import OUT_OF_MEMORY, address_space_cap, blob_splats, colours_differ, needs_prlimit, stripes
from .conftest import SHARED

pytestmark = pytest.mark.blender

TEXTURES = sorted(glob.glob(str(SHARED / "data" / "textures" / "*.jpg")))


@pytest.fixture
def inputs(tmp_path) -> dict[str, Path]:
    """A small splat scene and a stripe texture on disk."""
    ply, texture = tmp_path / "blob.ply", tmp_path / "stripes.png"
    write_ply(ply, blob_splats(600))
    write_png(texture, (stripes() * 255).astype(np.uint8))
    return {"ply": ply, "texture": texture}


@pytest.fixture
def blob(fresh, inputs):
    """The small scene imported as the active splat object, with small, fast transfer settings."""
    assert fresh.ops.gt2gs.import_ply(filepath=str(inputs["ply"])) == {"FINISHED"}
    settings = fresh.context.scene.gt2gs
    settings.texture_path = str(inputs["texture"])
    settings.preset = "preview"
    settings.stylise_steps, settings.resolution, settings.n_angles, settings.n_views = 6, 48, 4, 3
    yield fresh.context.active_object
    for run in list(transfer_run.ACTIVE.values()):
        run.cancel()
        run.finish()
    transfer_run.OUTCOMES.clear()


def snapshot() -> dict:
    """Every object, point cloud and point attribute of the file (to prove a run left them as they were)."""
    state = {
        "objects": sorted(o.name for o in bpy.data.objects),
        "clouds": sorted(c.name for c in bpy.data.pointclouds),
    }
    for cloud in bpy.data.pointclouds:
        for attr in cloud.attributes:
            if attr.data_type == "FLOAT":
                values = np.empty(len(cloud.points), np.float32)
                attr.data.foreach_get("value", values)
                state[(cloud.name, attr.name)] = values
    return state


def same(a: dict, b: dict) -> bool:
    return a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a)


@pytest.fixture(autouse=True)
def private_temp(tmp_path, monkeypatch):
    """Jobs of this test in a folder of its own, so other runs on the machine cannot change what it counts."""
    folder = tmp_path / "tmp"
    folder.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(folder))


def job_folders() -> set[str]:
    return set(glob.glob(os.path.join(tempfile.gettempdir(), "gt2gs_job_*")))


def dc(obj) -> np.ndarray:
    scene, _ = splats.object_to_scene(obj)
    return scene.sh_dc


def tick_until(run, condition, timeout: float = 120.0) -> JobStatus:
    """What the modal operator's timer does, driven by the test."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        status = run.tick(bpy.context)
        if condition(status):
            return status
        time.sleep(0.05)
    raise AssertionError(f"timed out: {run.job.status} {run.job.stderr_tail()}")


def test_transfer_operator_headless_adds_a_new_object(blob, capfd):
    before, folders, original = snapshot(), job_folders(), dc(blob)
    assert bpy.ops.gt2gs.transfer_texture(preset="preview", n_views=3) == {"FINISHED"}
    lines = [line for line in capfd.readouterr().out.splitlines() if line.startswith("gt2gs: ")]
    assert any(line.startswith("gt2gs: Stylising") and "%" in line for line in lines), lines  # headless progress
    result = bpy.context.active_object
    assert result.name == "blob GT²" and splats.is_splat_object(result)
    assert colours_differ(dc(result), original)
    assert np.array_equal(dc(blob), original)
    after = snapshot()
    assert all(np.array_equal(after[k], v) for k, v in before.items() if k not in ("objects", "clouds"))
    assert job_folders() == folders
    outcome = transfer_run.OUTCOMES["transfer"]
    view = transfer_view(blob.name, None, outcome)
    shown = result_view(outcome, view.message, view.icon)
    assert view.state == DONE and dict(shown.rows)["Result"] == "new object 'blob GT²' in 'Scene Collection'"
    assert shown.message == ""  # the main panel's message says it once, with the hidden original
    assert blob.hide_get() and result.visible_get()  # the result takes the original's place on screen
    assert re.fullmatch(r"Done in \d+ s; the original 'blob' is hidden \(Alt\+H shows it\)", view.message)
    # a second run would restyle the result (the active object): the panel says so and how to start from the original
    blob.name = "hero"
    hint = "Restyles blob GT², a result; set Target to hero to start from the original"
    assert transfer_run.result_target_hint(bpy.context) == hint
    bpy.context.scene.gt2gs.target = blob
    assert transfer_run.result_target_hint(bpy.context) is None
    bpy.context.scene.gt2gs.target = None
    bpy.data.objects.remove(blob)  # the original deleted: nothing to point to
    assert transfer_run.result_target_hint(bpy.context) is None


def test_transfer_in_place_replaces_the_splats(blob):
    bpy.context.scene.gt2gs.result_mode = "IN_PLACE"
    names, original = sorted(o.name for o in bpy.data.objects), dc(blob)
    assert bpy.ops.gt2gs.transfer_texture() == {"FINISHED"}
    assert sorted(o.name for o in bpy.data.objects) == names
    assert colours_differ(dc(bpy.data.objects["blob"]), original)
    assert len(bpy.data.pointclouds) == 1 and "UNDO" in bpy.types.GT2GS_OT_transfer_texture.bl_options


def test_modal_cycle_streams_progress_and_preview_then_applies(blob):
    run = transfer_run.TransferRun.start(bpy.context, {})
    assert not bpy.ops.gt2gs.transfer_texture.poll()  # one transfer at a time
    texts = []
    status = run.tick(bpy.context)
    while not status.finished:
        view = transfer_view(blob.name, status, None)
        assert view.state == RUNNING and view.can_cancel and not view.can_transfer
        texts.append(view.progress_text)
        time.sleep(0.05)
        status = run.tick(bpy.context)
    assert status.state == DONE and any(t.startswith("Stylising") for t in texts)
    assert tuple(transfer_run._previews["collection"][transfer_run.PREVIEW_KEY].image_size) == (48, 48)
    assert run.result_name in bpy.data.objects
    assert run.finish().state == DONE and not run.job.folder.exists() and not transfer_run.ACTIVE


def test_a_result_lands_on_its_own_original_whatever_it_and_others_are_called_now(blob, inputs):
    """The artist renames the original while it is restyled and brings in another scan under its old name: In Place
    writes onto the original (it once wrote onto the newcomer, and a rename alone threw the result away)."""
    bpy.context.scene.gt2gs.result_mode = "IN_PLACE"
    original = dc(blob)
    run = transfer_run.TransferRun.start(bpy.context, {})
    tick_until(run, lambda s: s.stage is not None)
    blob.name = "blob_hero"
    assert bpy.ops.gt2gs.import_ply(filepath=str(inputs["ply"])) == {"FINISHED"}
    newcomer = bpy.context.active_object
    newcomer.name = "blob"
    kept = dc(newcomer)
    assert tick_until(run, lambda s: s.finished).state == DONE
    run.finish()
    assert run.result_name == "blob_hero" and colours_differ(dc(bpy.data.objects["blob_hero"]), original)
    assert np.array_equal(dc(bpy.data.objects["blob"]), kept)


@pytest.mark.parametrize("mode", ["NEW", "IN_PLACE"])
def test_a_transfer_started_in_edit_mode_applies_its_result(blob, mode):
    """Select Part leaves the object in Edit Mode; the result is made by operators that need Object Mode, so the run
    once ended in a traceback, left itself running for the rest of the session and its job folder behind."""
    bpy.context.scene.gt2gs.result_mode = mode
    assert bpy.ops.object.mode_set(mode="EDIT") == {"FINISHED"}
    assert bpy.ops.gt2gs.transfer_texture() == {"FINISHED"}
    outcome = transfer_run.OUTCOMES["transfer"]
    assert outcome.state == DONE and not transfer_run.ACTIVE and not job_folders()
    assert bpy.context.mode == "OBJECT" and splats.is_splat_object(bpy.data.objects[outcome.result])


def test_live_preview_without_a_texture_waits_quietly(blob, capfd):
    """Live Orientation Preview on and no texture yet: dragging the angle printed a traceback at every step."""
    settings = bpy.context.scene.gt2gs
    settings.texture_path = ""
    settings.auto_preview = True
    for degrees in (10.0, 20.0, 30.0):
        settings.angle = math.radians(degrees)
    out, err = capfd.readouterr()
    assert "Traceback" not in out + err and not transfer_run.ACTIVE


def test_cancel_mid_run_leaves_the_scene_and_no_files(blob):
    bpy.context.scene.gt2gs.stylise_steps = 400
    before = snapshot()
    run = transfer_run.TransferRun.start(bpy.context, {})
    tick_until(run, lambda s: s.stage == "stylise" and s.step >= 2)
    run.cancel_requested = True  # what the Cancel button does; the modal operator then calls:
    run.cancel()
    assert run.tick(bpy.context).state == CANCELLED
    outcome = run.finish()
    assert outcome.state == CANCELLED and same(snapshot(), before)
    assert not run.job.folder.exists() and not transfer_run.ACTIVE
    assert transfer_view(blob.name, None, outcome).message == "Cancelled; the scene is unchanged"


def test_a_second_transfer_while_one_runs_is_refused(blob):
    bpy.context.scene.gt2gs.stylise_steps = 400
    before = snapshot()
    run = transfer_run.TransferRun.start(bpy.context, {})
    tick_until(run, lambda s: s.stage is not None)
    with pytest.raises(transfer_run.RunError, match="already running; cancel it first"):
        transfer_run.TransferRun.start(bpy.context, {})
    run.cancel()
    run.tick(bpy.context)
    run.finish()
    assert same(snapshot(), before) and not run.job.folder.exists() and not transfer_run.ACTIVE


def test_killed_worker_is_a_clear_error_and_the_scene_is_unchanged(blob):
    bpy.context.scene.gt2gs.stylise_steps = 400
    before = snapshot()
    run = transfer_run.TransferRun.start(bpy.context, {})
    tick_until(run, lambda s: s.stage == "stylise")
    os.kill(run.job.process.pid, signal.SIGKILL)
    status = tick_until(run, lambda s: s.finished, timeout=20)
    assert status.state == ERROR and "worker process was killed by signal 9" in status.error
    assert f"when memory runs out: {MEMORY_ADVICE}" in status.error
    outcome = run.finish()
    assert same(snapshot(), before) and not run.job.folder.exists()
    view = transfer_view(blob.name, None, outcome)
    assert view.state == ERROR and view.message.startswith("Failed: the worker process was killed")


@needs_prlimit
def test_worker_out_of_memory_is_a_clear_error_and_the_scene_is_unchanged(blob):
    """A real allocation failure: the worker's address space is capped as it starts, then it is asked
    for 4096 px views on the CPU."""
    settings = bpy.context.scene.gt2gs
    settings.resolution = 4096
    before, folders, cap = snapshot(), job_folders(), address_space_cap()
    run = transfer_run.TransferRun.start(bpy.context, {})
    resource.prlimit(run.job.process.pid, resource.RLIMIT_AS, (cap, cap))
    status = tick_until(run, lambda s: s.finished)
    assert status.state == ERROR and OUT_OF_MEMORY.fullmatch(status.error), status.error
    outcome = run.finish()
    assert same(snapshot(), before) and job_folders() == folders and not transfer_run.ACTIVE
    assert transfer_view(blob.name, None, outcome).message == f"Failed: {status.error}"


def test_unusable_texture_is_reported_and_nothing_starts(blob):
    folders = job_folders()
    with pytest.raises(RuntimeError, match="texture file not found"):
        bpy.ops.gt2gs.transfer_texture(texture_path="/nonexistent/wood.jpg")
    with pytest.raises(RuntimeError, match="unknown preset 'ultra'"):
        bpy.ops.gt2gs.transfer_texture(preset="ultra")
    bpy.context.scene.gt2gs.texture_path = ""  # nothing chosen: say so, not "not found: <working folder>"
    with pytest.raises(RuntimeError, match=r"choose a texture file \(or an image\) first"):
        bpy.ops.gt2gs.transfer_texture()
    assert job_folders() == folders and not transfer_run.ACTIVE


def test_region_uses_the_point_selection(blob):
    bpy.context.scene.gt2gs.region_only = True
    with pytest.raises(RuntimeError, match="no point selection"):
        bpy.ops.gt2gs.transfer_texture()
    selection = blob.data.attributes.new(transfer_run.SELECTION_ATTRIBUTE, "BOOLEAN", "POINT")
    mask = np.zeros(len(blob.data.points), bool)
    mask[::3] = True
    selection.data.foreach_set("value", mask)
    assert np.array_equal(transfer_run.selected_points(blob), np.flatnonzero(mask))
    run = transfer_run.TransferRun.start(bpy.context, {})
    assert np.array_equal(np.load(run.job.path("region.npy")), np.flatnonzero(mask))
    assert tick_until(run, lambda s: s.finished).state == DONE
    run.finish()
    result = bpy.data.objects[run.result_name]
    kept = np.flatnonzero(~mask)
    assert np.array_equal(dc(result)[: len(kept)], dc(blob)[kept])  # unselected splats untouched


def test_preview_orientation_operator_fills_the_preview(blob):
    assert bpy.ops.gt2gs.preview_orientation(angle=30.0) == {"FINISHED"}
    preview = transfer_run._previews["collection"][transfer_run.PREVIEW_KEY]
    assert tuple(preview.image_size) == (256, 256)
    pixels = np.empty(256 * 256 * 4, np.float32)
    preview.image_pixels_float.foreach_get(pixels)
    assert pixels.reshape(-1, 4)[:, :3].std() > 0.05  # texture and background, not a flat image
    assert transfer_run.OUTCOMES["preview"].state == DONE


def test_image_datablock_texture_goes_as_pixels(blob):
    from gt2gs_blender.blender.job import Job

    image = bpy.data.images.new("tex", 8, 4)
    pixels = np.zeros((4, 8, 4), np.float32)
    pixels[..., 3] = 1.0
    pixels[3, :, 0] = 1.0  # the top row (Blender stores rows bottom-up) is red
    image.pixels.foreach_set(pixels.ravel())
    settings = bpy.context.scene.gt2gs
    settings.texture_source, settings.texture_image = "IMAGE", image
    job = Job()
    try:
        name = transfer_run.texture_spec(bpy.context, job, None)
        saved = np.load(job.path(name))
        assert saved.shape == (4, 8, 3) and saved[0, :, 0].min() == 1.0 and saved[1:, :, 0].max() == 0.0
    finally:
        job.cleanup()


def engine_cameras():
    """The engine's cameras.json reader; its Camera is torch's (skipped on a bpy whose Python has no torch here)."""
    pytest.importorskip("torch", exc_type=ModuleNotFoundError, reason="the engine's Camera needs torch")
    from gt2gs_blender.core.cameras.cameras_json import load_cameras_json

    return load_cameras_json


def test_scene_cameras_become_views_in_object_space(fresh):
    load_cameras_json = engine_cameras()
    scene = fresh.context.scene
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 640, 480, 50
    cam_data = fresh.data.cameras.new("cam")
    cam_data.lens, cam_data.sensor_width = 50.0, 36.0
    cam = fresh.data.objects.new("cam", cam_data)
    scene.collection.objects.link(cam)
    cam.location = (0.0, -5.0, 1.0)
    cam.rotation_euler = (np.pi / 2, 0.0, 0.0)  # looks along +y, z up
    fresh.context.view_layer.update()
    object_to_world = np.eye(4)
    object_to_world[:3, 3] = (0.0, 0.0, 1.0)  # the PLY's origin sits at world (0, 0, 1)
    entries = views.camera_entries([cam], scene, object_to_world)
    path = Path(tempfile.mkdtemp()) / "cameras.json"
    path.write_text(__import__("json").dumps(entries))
    (camera,) = load_cameras_json(path)
    assert (camera.width, camera.height) == (320, 240) and np.isclose(camera.fx, 50 / 36 * 320)
    uv, depth = camera.project(np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.5]]))
    assert np.allclose(uv[0], (160, 120)) and np.isclose(depth[0], 5.0)
    assert np.allclose(uv[1], (160 + camera.fx / 5, 120 - camera.fy * 0.5 / 5))  # right and up on screen


def test_a_core_camera_becomes_a_blender_camera_that_sees_the_same(fresh):
    """add_camera then camera_entries gives back the core camera: same size, focal length and projection."""
    load_cameras_json = engine_cameras()
    from gt2gs_blender.core.cameras.poses import look_at

    scene = fresh.context.scene
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 200, 120, 100
    view = look_at((1.0, -3.0, 2.0), (0.2, 0.1, 0.0), width=200, height=120, fov_deg=50.0, up=(0.0, 0.0, 1.0))
    obj = views.add_camera(view, scene.collection, "first view")
    fresh.context.view_layer.update()
    path = Path(tempfile.mkdtemp()) / "cameras.json"
    path.write_text(__import__("json").dumps(views.camera_entries([obj], scene, np.eye(4))))
    (back,) = load_cameras_json(path)
    points = np.array([[0.0, 0.0, 0.0], [0.5, -0.3, 0.4], [-0.4, 0.6, -0.2]])
    assert (back.width, back.height) == (200, 120) and np.isclose(back.fx, view.fx)
    assert np.allclose(back.project(points)[0], view.project(points)[0], atol=1e-6)


def test_panel_settings_and_keywords_become_the_job_config(fresh):
    from gt2gs_blender.core.transfer.presets import PRESETS
    from gt2gs_blender.core.transfer.presets import preset as make_preset

    settings = fresh.context.scene.gt2gs
    preset, config = transfer_run.config_overrides(fresh.context, {})
    assert preset == "fast" and make_preset(preset, **config) == PRESETS["fast"]  # a new scene shows the preset
    settings.preset = "balanced"  # choosing a preset shows its values in every setting
    preset, config = transfer_run.config_overrides(fresh.context, {})
    assert preset == "balanced" and config["resolution"] == 384 and make_preset(preset, **config) == PRESETS["balanced"]
    settings.stylise_steps, settings.gpb, settings.angle, settings.texture_height = 12, False, math.radians(15), 96
    settings.stylise_geometry, settings.depth_ratio, settings.object_backdrop = "on", 2.0, True
    settings.background = (0.0, 0.5, 1.0)
    _, config = transfer_run.config_overrides(fresh.context, {})
    made = make_preset("balanced", **config)
    assert (made.stylise_steps, made.gpb, made.angle, made.texture_height) == (12, False, 15.0, 96)
    assert made.stylise_geometry == "on" and made.depth_ratio == 2.0 and made.object_backdrop
    assert made.background == (0.0, 0.5, 1.0) and made.resolution == 384
    preset, config = transfer_run.config_overrides(fresh.context, {"preset": "preview", "angle": -30.0})
    assert preset == "preview" and config == {"angle": -30.0}  # a script's preset is that preset exactly


def test_transfer_view_in_each_state():
    idle = transfer_view(None, None, None)
    assert (idle.state, idle.can_transfer, idle.can_cancel, idle.progress) == (IDLE, False, False, None)
    assert transfer_view("donut", None, None).can_transfer
    running = transfer_view(
        "donut",
        JobStatus(
            state=RUNNING,
            stage="stylise",
            step=12,
            total=40,
            fraction=0.45,
            eta_s=65.2,
            message="stylise: texture loss 0.3",
        ),
        None,
    )
    assert running.state == RUNNING and running.can_cancel and not running.can_transfer
    assert running.progress == 0.45 and running.progress_text == "Stylising 12/40 · 45% · ETA 1:05"
    report = {
        "seconds": 12.34,
        "n_gaussians": 45624,
        "n_views": 8,
        "image_size": [128, 128],
        "device": "cpu",
        "weights": {"spec": "vgg19_norm_relu3", "fallback": False},
        "metrics": {
            "texture_match_start": 0.3,
            "texture_match": 0.2,
            "ssim": 0.81,
            "object_ssim": 0.42,
            "object_ssim_blurred": 0.73,
            "preview_ssim": 0.62,
        },
    }
    outcome = transfer_run.Outcome(DONE, "done in 15 s", report, "donut GT²", 15.2, mode="IN_PLACE")
    done = transfer_view("donut", None, outcome)
    rows = dict(result_view(outcome, done.message, done.icon).rows)
    assert done.state == DONE and done.message == "Done in 15 s" and done.progress is None
    assert rows["Time"] == "15 s (texture transfer 12 s)"  # the wait the user saw, beside the engine's part
    assert rows["Result"] == "'donut GT²' (no longer in the file)" and rows["Splats"] == "45,624"
    assert rows["Views"] == "8 at 128×128" and rows["Frame SSIM (Paper)"] == "0.810"
    assert rows["Scene Kept (SSIM)"] == "0.420" and rows["Parts Kept (SSIM)"] == "0.730"
    assert rows["Texture Match"] == "0.300 → 0.200" and rows["Weights"] == "vgg19_norm_relu3"
    assert rows["Like the Preview (SSIM)"] == "0.620"
    assert result_view(None, "", "").message == NO_RUN_TEXT
    error_outcome = transfer_run.Outcome(ERROR, "the worker process exited with status 1")
    error = transfer_view("donut", None, error_outcome)
    assert error.state == ERROR and error.icon == "ERROR" and error.can_transfer
    assert error.message == "Failed: the worker process exited with status 1"
    failed = result_view(error_outcome, error.message, error.icon)
    assert not failed.rows and failed.message == error.message  # no rows: the sub-panel says why
    # no weights: a warning box before any run; no CUDA with a GPU-only preset: Transfer disabled, and why
    fallback = machine.MachineState(info={"cuda": False, "weights": {"fallback": True}})
    no_weights = transfer_view("donut", None, None, warnings=machine_warnings(fallback))
    assert no_weights.can_transfer and no_weights.warnings == [NO_WEIGHTS_WARNING]
    blocker = machine.gpu_problem("paper-360", "auto", fallback)
    no_cuda = transfer_view("donut", None, None, blocker=blocker)
    assert not no_cuda.can_transfer and "needs" not in blocker and "no CUDA GPU was found" in no_cuda.warnings[0]
    assert machine.gpu_problem("fast", "auto", fallback) is None
    assert machine.gpu_problem("paper-llff", "auto", machine.MachineState()) is None  # not known yet
    assert "Device preference is CPU" in machine.gpu_problem("paper-llff", "cpu", machine.MachineState())
    assert machine.gpu_problem("paper-llff", "auto", machine.MachineState(info={"cuda": True})) is None
    assert transfer_view("donut", None, transfer_run.Outcome(CANCELLED, "cancelled")).icon == "CANCEL"
    assert eta_text(None) == "" and eta_text(5) == "ETA 0:05"


def test_preferences_install_command_and_status(fresh, monkeypatch):
    from gt2gs_blender.operators.dependencies import GT2GS_OT_install_dependencies, install_commands
    from gt2gs_blender.panels.preferences import GT2GS_AP_preferences, dependency_rows

    assert GT2GS_AP_preferences.bl_idname == "gt2gs_blender"
    commands = install_commands("CUDA", "/user/extensions/.user/gt2gs_blender/deps")
    assert commands[-1] == deps.install_command(sys.executable, "/user/extensions/.user/gt2gs_blender/deps", "CUDA")
    assert all(command[0] == sys.executable for command in commands)
    pinned = deps.PINS_BY_PYTHON[sys.version_info[:2]]  # this Blender's Python has pins: 3.11 or 3.13
    assert {f"{name}=={version}" for name, version in pinned.items()} <= set(commands[-1])
    assert not GT2GS_OT_install_dependencies.poll(fresh.context)  # offline here, and not an installed extension
    monkeypatch.setattr(machine, "_state", machine.MachineState())
    before = {module: ok for module, _, ok in dependency_rows(None, machine.current())}
    assert before == {m: importlib.util.find_spec(m) is not None for m in ("torch", "numpy", "cv2")}
    machine.probe({}, None)  # imports them in the worker's Python (this one, or GT2GS_WORKER_PYTHON's)
    rows = {module: ok for module, _, ok in dependency_rows(None, machine.current())}
    assert rows == {"torch": True, "numpy": True, "cv2": True}


def test_packages_built_for_another_python_are_shown_as_not_loading(fresh, monkeypatch):
    """The deps folder holds packages built for another Python (the issue's 5.2 window showed them as installed):
    the machine check imports them in the worker's Python, and the preferences say which do not load and why."""
    from gt2gs_blender.panels.preferences import dependency_rows, machine_rows

    if worker_python() == sys.executable:
        pytest.skip("needs a worker Python other than this one (GT2GS_WORKER_PYTHON, as make test-blender52 sets)")
    this_pythons_packages = str(Path(np.__file__).parents[1])  # numpy built for this Python, not the worker's
    monkeypatch.setattr(machine, "_state", machine.MachineState())
    info, error = machine.probe({}, this_pythons_packages)
    assert info is None and re.search(r"numpy does not load: \w*Error: .*_multiarray_umath", error), error
    rows = {module: (found, ok) for module, found, ok in dependency_rows(this_pythons_packages, machine.current())}
    assert rows["numpy"][0].startswith("does not load: ") and not rows["numpy"][1]
    assert machine_rows(machine.current()) == [("Machine", error, "ERROR")]


def test_batch_script_runs_and_fails_readably(fresh, inputs, tmp_path, capsys):
    from gt2gs_blender import batch

    out = tmp_path / "out.ply"
    code = batch.main(
        [
            "--ply",
            str(inputs["ply"]),
            "--texture",
            str(inputs["texture"]),
            "--out",
            str(out),
            "--preset",
            "preview",
            "--views",
            "2",
            "--angle",
            "30",
        ]
    )
    assert code == 0 and out.is_file()
    assert (
        batch.main(["--ply", str(tmp_path / "missing.ply"), "--texture", str(inputs["texture"]), "--out", str(out)])
        == 1
    )
    assert "gt2gs: error: " in capsys.readouterr().err
    assert (
        batch.main(
            ["--ply", str(inputs["ply"]), "--texture", str(inputs["texture"]), "--out", str(out), "--preset", "ultra"]
        )
        == 1
    )
    captured = capsys.readouterr()
    lines = captured.err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("gt2gs: error: unknown preset 'ultra'; choose one of preview")
    assert "ultra" not in captured.out  # Blender's echo of the operator's error is left out: said once


@pytest.mark.slow
def test_preview_preset_on_the_shared_donut(fresh, donut, monkeypatch):
    """The issue's acceptance: the donut, a real texture, real weights, the preview preset, headless."""
    if not TEXTURES:
        pytest.skip("shared textures not found")
    monkeypatch.setenv("GT2GS_WEIGHTS_DIR", str(SHARED / "weights"))
    assert fresh.ops.gt2gs.import_ply(filepath=str(donut)) == {"FINISHED"}
    source = fresh.context.active_object
    original = dc(source)
    started = time.perf_counter()
    assert fresh.ops.gt2gs.transfer_texture(texture_path=TEXTURES[0], preset="preview") == {"FINISHED"}
    seconds = time.perf_counter() - started
    result = fresh.context.active_object
    assert result != source and colours_differ(dc(result), original, tol=0.05)
    assert np.array_equal(dc(source), original)
    report = transfer_run.OUTCOMES["transfer"].report
    assert report["weights"]["fallback"] is False
    print(f"donut preview preset through the operator: {seconds:.1f} s")
    transfer_run.OUTCOMES.clear()


def test_every_setting_has_a_blender_property_unless_internal(fresh):
    from gt2gs_blender.core.transfer.config import SETTINGS
    from gt2gs_blender.core.transfer.setting import IN_PREFERENCES, IN_SCENE
    from gt2gs_blender.panels.preferences import GT2GS_AP_preferences

    scene_props = fresh.types.Scene.bl_rna.properties["gt2gs"].fixed_type.properties
    prefs_props = GT2GS_AP_preferences.__annotations__
    where = {IN_SCENE: set(scene_props.keys()), IN_PREFERENCES: set(prefs_props)}
    missing = [name for name, meta in SETTINGS.items() if not meta.internal and name not in where[meta.blender]]
    assert not missing, f"settings without a Blender property: {missing}"
    for name, meta in SETTINGS.items():
        if meta.blender == IN_SCENE and not meta.internal:
            assert scene_props[name].name == meta.label and scene_props[name].description.startswith(meta.help)


def test_batch_refuses_a_result_of_the_fallback_network_unless_allowed(fresh, inputs, tmp_path, capsys, monkeypatch):
    from gt2gs_blender import batch

    empty = tmp_path / "no_weights"
    empty.mkdir()
    monkeypatch.setenv("TORCH_HOME", str(empty))  # no torch hub cache either
    monkeypatch.setenv("GT2GS_WEIGHTS_DIR", str(empty))
    out = tmp_path / "out.ply"
    argv = ["--ply", str(inputs["ply"]), "--texture", str(inputs["texture"]), "--out", str(out)]
    argv += ["--preset", "preview", "--views", "2", "--weights", str(empty)]
    assert batch.main(argv) == 1 and not out.exists()
    assert "a random network stood in" in capsys.readouterr().err
    assert batch.main([*argv, "--allow-fallback-weights"]) == 0 and out.is_file()
    view = transfer_view("blob", None, transfer_run.OUTCOMES["transfer"])
    assert view.icon == "ERROR" and "random network stood in" in view.message  # the panel says it too


def test_the_orientation_is_an_angle_property_in_degrees_for_the_engine(fresh):
    prop = fresh.types.Scene.bl_rna.properties["gt2gs"].fixed_type.properties["angle"]
    assert prop.subtype == "ANGLE"
    fresh.context.scene.gt2gs.angle = math.radians(-42.5)
    assert transfer_run.config_overrides(fresh.context, {})[1]["angle"] == -42.5


def test_sub_panels_group_every_scene_setting_in_artists_terms(fresh):
    from gt2gs_blender.core.transfer.config import user_settings
    from gt2gs_blender.core.transfer.setting import IN_SCENE, PARTS
    from gt2gs_blender.panels import sections

    assert set(PARTS) <= set(sections.SECTION_OF_PART) and sections.section_of("a new part") == "Advanced"
    listed = [name for s in sections.SECTIONS for _, names in sections.section_settings(s) for name in names]
    listed += [name for section in sections.SECTIONS for name in sections.front_settings(section)]
    assert sorted(listed) == sorted(name for name, _, _ in user_settings(IN_SCENE))  # each exactly once
    # Texture: what an artist sets (what the texture keeps of the scene); the method's texture settings: Advanced
    assert sections.front_settings("Texture") == [
        "angle",
        "texture_repeats",
        "texture_offset_right",
        "texture_offset_up",
        "texture_softness",
        "keep_scene",
        "keep_material",
        "scene_colour",
        "keep_accents",
        "keep_hues",
        "scene_brightness",
    ]
    assert sections.section_settings("Texture") == []
    assert {"texture", "gt2"} <= set(dict(sections.section_settings("Advanced")))  # by part: new ones join
    labels = [cls.bl_label for cls in sections.classes]
    assert labels == ["Texture", "Views", "Quality", "Advanced"]
    assert all(hasattr(fresh.types, cls.__name__) for cls in sections.classes)
    assert hasattr(fresh.types, "VIEW3D_PT_gt2gs_result")


def test_automatic_settings_show_the_value_a_run_uses():
    from gt2gs_blender.panels.sections import effective_text

    assert effective_text("depth_ratio", 0.0) == "Uses measured from the views, at most 2×"
    assert effective_text("depth_ratio", 2.0) is None
    assert effective_text("match_channels", 0) == "Uses all channels of the feature network"
    assert effective_text("threads", 0, {"threads": 6}) == "Uses 6 (one per physical core)"
    assert effective_text("plateau_window", 0) == "Uses every step of every phase"
    assert effective_text("dedup_threshold", 0.0) == "Uses every texture bank entry kept"
    assert effective_text("gpb", False) is None and effective_text("seed", 0) is None  # 0 is a value there
    assert effective_text("stylise_geometry", "auto", {"front": True}) == "Uses On: the views all look from the front"
    assert effective_text("layout_projection", "auto", {"front": False}) == "Uses Box: the views surround it"
    assert effective_text("stylise_geometry", "auto", {"front": None}) is None  # no views to tell yet
    assert effective_text("stylise_geometry", "off", {"front": True}) is None
    assert effective_text("texture_softness", 0.0) == "At 0: the photo as it is"


def test_the_panel_tells_whether_the_views_look_from_the_front(fresh, tmp_path):
    """What the automatic Projection and Texture Moves Splats follow, from each source of views: automatic
    views ring the object (or look out from inside it) unless one or Front; scene cameras and a cameras.json
    count by where they look."""
    from mathutils import Euler

    from gt2gs_blender.blender.views import views_from_front

    scene = fresh.context.scene
    settings = scene.gt2gs
    settings.view_source, settings.n_views = "AUTO", 16
    assert views_from_front(settings, scene) is False
    settings.n_views = 1
    assert views_from_front(settings, scene) is True
    settings.n_views, settings.view_kind = 16, "front"
    assert views_from_front(settings, scene) is True  # the front arc looks from one side
    settings.view_kind = "inside"
    assert views_from_front(settings, scene) is False  # views from inside a room look out all round
    settings.view_kind = "orbit"
    settings.view_source = "SCENE_CAMERAS"
    assert views_from_front(settings, scene) is None  # no camera yet
    for name, x, turn in (("left", -1.0, 10.0), ("right", 1.0, -10.0)):
        camera = fresh.data.objects.new(name, fresh.data.cameras.new(name))
        camera.location = (x, -5.0, 0.0)
        camera.rotation_euler = Euler((math.radians(90.0), 0.0, math.radians(turn)))  # looking along +y
        scene.collection.objects.link(camera)
    fresh.context.view_layer.update()
    assert views_from_front(settings, scene) is True  # a capture seen from the front
    behind = fresh.data.objects.new("behind", fresh.data.cameras.new("behind"))
    behind.location, behind.rotation_euler = (0.0, 5.0, 0.0), Euler((math.radians(90.0), 0.0, math.radians(180.0)))
    scene.collection.objects.link(behind)
    fresh.context.view_layer.update()
    assert views_from_front(settings, scene) is False  # one looks back: an orbit
    path = tmp_path / "cameras.json"
    forward = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]  # OpenCV camera-to-world: looks along +z
    back = [[-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]]
    path.write_text(json.dumps([{"rotation": forward}, {"rotation": forward}]), encoding="utf-8")
    settings.view_source, settings.cameras_json = "CAMERAS_JSON", str(path)
    assert views_from_front(settings, scene) is True
    path.write_text(json.dumps([{"rotation": forward}, {"rotation": back}]), encoding="utf-8")
    os.utime(path, (1e9, 1e9))  # a new modification time: read again
    assert views_from_front(settings, scene) is False
    settings.cameras_json = str(tmp_path / "missing.json")
    assert views_from_front(settings, scene) is None


def test_settings_a_run_ignores_are_greyed_out(fresh):
    """Texture Size counts only at Texture Repeats 0; the layout's split and strength only with the layout on,
    Scene Softness only while Keep Scene or Scene Colour is above 0, Keep Material only while Keep Scene or Scene
    Brightness is."""
    from gt2gs_blender.panels.sections import USED_WHEN, setting_used

    settings = fresh.context.scene.gt2gs
    assert set(USED_WHEN) <= set(type(settings).__annotations__)
    settings.texture_repeats, settings.layout = 1.5, True
    assert not setting_used(settings, "texture_height") and setting_used(settings, "split_size")
    assert setting_used(settings, "shade_softness")
    settings.keep_scene = 0.0
    assert setting_used(settings, "shade_softness")  # the colour it keeps is still averaged over it
    assert setting_used(settings, "keep_accents")
    settings.scene_colour = 0.0
    assert not setting_used(settings, "shade_softness") and setting_used(settings, "keep_scene")
    assert setting_used(settings, "keep_material")  # Scene Brightness still takes its share of the exposure
    settings.scene_brightness = 0.0
    assert not setting_used(settings, "keep_material")  # neither a shade nor an exposure left to take it
    assert not setting_used(settings, "keep_accents")  # the texture alone: no colour of the scene to raise
    assert not setting_used(settings, "keep_hues")  # nor a part's hue to tint it with
    settings.texture_repeats, settings.layout = 0.0, False
    assert setting_used(settings, "texture_height") and not setting_used(settings, "lambda_layout")
    assert setting_used(settings, "angle")


def test_texture_thumbnail_leaves_no_image_datablock(blob, inputs):
    from gt2gs_blender.blender import textures

    settings = bpy.context.scene.gt2gs
    images = len(bpy.data.images)
    preview = textures.thumbnail(settings)
    assert preview is not None and max(preview.image_size) > 0 and len(bpy.data.images) == images
    assert textures.thumbnail(settings) == preview  # loaded once, not at every redraw
    settings.texture_source = "IMAGE"
    assert textures.thumbnail(settings) is None
    settings.texture_image = bpy.data.images.new("tex", 8, 8)
    assert textures.thumbnail(settings) is not None


def test_undecodable_texture_is_refused_before_the_worker_starts(blob, tmp_path):
    from gt2gs_blender.blender.textures import texture_problem

    folders, images = job_folders(), len(bpy.data.images)
    text = tmp_path / "notes.jpg"
    text.write_text("not a picture")
    with pytest.raises(RuntimeError, match=f"the texture {text} is not an image file: choose a PNG, JPEG"):
        bpy.ops.gt2gs.transfer_texture(texture_path=str(text))
    damaged = tmp_path / "damaged.png"
    damaged.write_bytes(b"\x89PNG\r\n\x1a\n" + b"\x00" * 40)
    with pytest.raises(RuntimeError, match=f"the texture {damaged} is a damaged PNG file"):
        bpy.ops.gt2gs.preview_orientation(texture_path=str(damaged))
    assert job_folders() == folders and not transfer_run.ACTIVE and len(bpy.data.images) == images
    assert texture_problem(str(bpy.context.scene.gt2gs.texture_path)) is None


def test_a_texture_refused_only_by_the_worker_or_a_folder_reads_as_a_failed_transfer(blob, tmp_path):
    """Blender decodes a truncated JPEG, the worker does not: the report says the transfer failed (it read "Texture
    transfer /path: ..."); a folder given as the texture says so (it read "texture file not found")."""
    before = snapshot()
    photo = Path(TEXTURES[0]).read_bytes() if TEXTURES else pytest.skip("needs the shared texture photos")
    cut = tmp_path / "cut.jpg"
    cut.write_bytes(photo[: len(photo) // 2])
    with pytest.raises(RuntimeError, match=f"Texture transfer failed: {cut}: "):
        bpy.ops.gt2gs.transfer_texture(texture_path=str(cut))
    with pytest.raises(RuntimeError, match=f"{tmp_path}: the texture is a folder; choose an image file in it"):
        bpy.ops.gt2gs.transfer_texture(texture_path=str(tmp_path))
    assert same(snapshot(), before) and not transfer_run.ACTIVE


def test_gpu_only_presets_are_marked_and_refused_without_cuda(blob, monkeypatch):
    from gt2gs_blender.core.transfer.presets import GPU_PRESETS
    from gt2gs_blender.panels.settings import PRESET_ITEMS

    marked = {name for name, label, _ in PRESET_ITEMS if label.endswith("(GPU)")}
    assert marked == GPU_PRESETS == {"paper-llff", "paper-360"}
    monkeypatch.setattr(machine, "_state", machine.MachineState(info={"cuda": False}))
    folders = job_folders()
    with pytest.raises(RuntimeError, match="'paper-llff' preset is the paper's schedule for a CUDA GPU"):
        bpy.ops.gt2gs.transfer_texture(preset="paper-llff")
    assert job_folders() == folders and not transfer_run.ACTIVE


def test_machine_check_runs_in_the_workers_python(fresh, tmp_path, monkeypatch):
    """The preferences' machine box from a real check: weights, rasterizer, compiler, CUDA, kernel cache."""
    from gt2gs_blender.panels.preferences import machine_rows, weights_offer

    empty = tmp_path / "no_weights"
    empty.mkdir()
    monkeypatch.setenv("GT2GS_WEIGHTS_DIR", str(empty))
    monkeypatch.setenv("TORCH_HOME", str(empty))
    monkeypatch.setattr(machine, "_state", machine.MachineState())
    assert machine_rows(machine.current()) == [("Machine", "not checked yet", "INFO")]
    info, error = machine.probe({"backend": "torch"}, None)
    assert error is None and info is machine.current().info and info["threads"] >= 1
    rows = {label: value for label, value, _ in machine_rows(machine.current())}
    assert rows["Weights"].startswith("none found: a RANDOM network")
    assert rows["Rasterizer"] == "portable torch (chosen in the preferences)"
    assert rows["CUDA"].startswith("not found" if not info["cuda"] else info["cuda_device"])
    assert rows["Kernel Cache"].startswith(info["kernel_cache"]) and rows["C++ Compiler"] == (
        info["compiler"] or "not found"
    )
    assert rows["Numba"].startswith(info["numba"] or "not installed")
    assert rows["Precision"] == f"{info['precision']} with Mixed Precision ({info['precision_note']})"
    assert info["precision"] in ("bfloat16", "float32")  # the CPU's (no CUDA device asked)
    offer, advice = weights_offer(machine.current(), online=True)
    assert offer and "https://download.pytorch.org/models/vgg16-397923af.pth" in advice
    offer, advice = weights_offer(machine.current(), online=False)
    assert not offer and advice.startswith("Allow Online Access") and "vgg16-397923af.pth" in advice
    assert machine_warnings(machine.current()) == [NO_WEIGHTS_WARNING]
    monkeypatch.setenv("GT2GS_WEIGHTS_DIR", str(SHARED / "weights"))
    if (SHARED / "weights" / "vgg19_normalised_to_relu3_1.pth").is_file():
        machine.probe({}, None)
        weights = {label: value for label, value, _ in machine_rows(machine.current())}["Weights"]
        assert weights.startswith("vgg19_norm_relu3 from ") and weights_offer(machine.current(), True) == (False, "")


def test_first_compile_of_the_kernel_is_a_progress_stage(monkeypatch):
    pytest.importorskip("torch", exc_type=ModuleNotFoundError, reason="the worker runs here, in this Python")
    from gt2gs_blender.app import worker
    from gt2gs_blender.core.render import cpu_backend, kernel_cache
    from gt2gs_blender.core.transfer.presets import preset

    built, events = [], []
    monkeypatch.setattr(kernel_cache, "is_built", lambda: bool(built))
    monkeypatch.setattr(cpu_backend, "load_kernel", lambda: built.append(True))
    worker._prepare_kernel(preset("fast", device="cpu"), events.append, lambda: False)
    assert built and [e.stage for e in events] == ["compile", "compile"] and "first run" in events[-1].message
    worker._prepare_kernel(preset("fast", device="cpu"), events.append, lambda: False)  # built: no stage
    worker._prepare_kernel(preset("fast", backend="torch"), events.append, lambda: False)
    assert len(events) == 2 and len(built) == 1
    status = JobStatus(state=RUNNING, stage="compile", fraction=0.0)
    assert transfer_view("blob", status, None).progress_text == "Compiling the CPU rasterizer (first run only) · 0%"


def test_orientation_preview_names_the_first_view_and_the_result_s_size(blob):
    """The caption names the view the angle is measured in, and how many splats the run will save: the
    layout's detail split (on in the preset) makes more than the object has, within Split Budget, and with
    Selected Points Only fewer, since only the selection splits."""
    assert bpy.ops.gt2gs.preview_orientation(n_views=2) == {"FINISHED"}
    assert transfer_run.preview_caption() == (
        "First view: automatic view 1, in front (Blender's Front view, from -Y), 20° above; "
        "the Orientation angle is measured here"
    )
    found = re.fullmatch(
        r"The result will have about ([\d,]+) splats, ([\d.]+)x the object's ([\d,]+)",
        transfer_run.preview_splats_text(),
    )
    assert found, transfer_run.preview_splats_text()
    start, ratio, count = int(found[1].replace(",", "")), float(found[2]), int(found[3].replace(",", ""))
    assert count == len(blob.data.points) < start <= bpy.context.scene.gt2gs.split_budget * count
    assert ratio == pytest.approx(start / count, abs=0.05)
    assert transfer_run.preview_views_text() == "The run works 2 views at 48×48"
    settings = bpy.context.scene.gt2gs
    settings.resolution, settings.dense_upscale = 16, 2.0  # 600 splats on ~80 px: 7.5 behind each, dense
    assert bpy.ops.gt2gs.preview_orientation(n_views=2) == {"FINISHED"}
    assert transfer_run.preview_views_text() == "The run works 2 views at 32×32: a dense capture, above Resolution's 16"
    settings.resolution, settings.dense_upscale = 48, 1.0
    selection = blob.data.attributes.new(transfer_run.SELECTION_ATTRIBUTE, "BOOLEAN", "POINT")
    selection.data.foreach_set("value", np.arange(count) % 3 == 0)
    bpy.context.scene.gt2gs.region_only = True  # the preview splits only the selected third, as the run will
    assert bpy.ops.gt2gs.preview_orientation(n_views=2) == {"FINISHED"}
    region_start = int(re.search(r"about ([\d,]+) splats", transfer_run.preview_splats_text())[1].replace(",", ""))
    assert count < region_start < start
    scene = bpy.context.scene
    scene.gt2gs.view_kind = "inside"
    assert transfer_run.first_view_label(bpy.context).startswith("automatic view 1, from inside, looking as Blender")
    scene.gt2gs.view_kind = "auto"
    for name in ("B cam", "A cam"):
        scene.collection.objects.link(bpy.data.objects.new(name, bpy.data.cameras.new(name)))
    scene.gt2gs.view_source = "SCENE_CAMERAS"
    assert transfer_run.first_view_label(bpy.context) == "camera 'A cam' (first by name)"


class RecordingLayout:
    """A stand-in for a panel's UILayout that records what ``draw`` lays out and checks every property and
    operator it names exists."""

    def __init__(self, shown: list) -> None:
        self.shown = shown

    def __getattr__(self, name: str):
        def call(*args, **kwargs):
            if name == "prop":
                assert hasattr(args[0], args[1]), args[1]
                self.shown.append(args[1])
            elif name == "operator":
                module, operator = args[0].split(".")
                assert hasattr(bpy.types, f"{module.upper()}_OT_{operator}"), args[0]
                self.shown.append(args[0])
            elif name == "label":
                self.shown.append(kwargs.get("text", ""))
            return RecordingLayout(self.shown)

        return call


def draw_panel(cls, context) -> list:
    shown: list = []
    cls.draw(SimpleNamespace(layout=RecordingLayout(shown)), context)
    return shown


def test_every_panel_draws_what_its_functions_say(blob):
    from gt2gs_blender.core.transfer.config import user_settings
    from gt2gs_blender.core.transfer.setting import IN_SCENE
    from gt2gs_blender.panels import result, sections, transfer_panel
    from gt2gs_blender.panels.sidebar import LABEL_CHARS, LINE_CHARS

    context = bpy.context
    main = draw_panel(transfer_panel.VIEW3D_PT_gt2gs_transfer, context)
    assert "gt2gs.transfer_texture" in main and transfer_panel.current_view(context).message in main
    texture = draw_panel(sections.classes[0], context)
    assert texture[:2] == ["texture_source", "texture_path"] and "angle" in texture and "texture_repeats" in texture
    assert "n_angles" not in texture and "Texture" not in texture  # no heading repeating the sub-panel's name
    views_shown = draw_panel(sections.classes[1], context)
    assert views_shown[:2] == ["view_source", "n_views"] and "Views" not in views_shown
    advanced = draw_panel(sections.classes[3], context)
    assert "dedup_threshold" in advanced and "n_angles" in advanced
    assert "Uses every texture bank entry kept" in advanced
    # labels longer than the default sidebar's label column get a row of their own (or the whole row: a checkbox)
    labels = {name: meta.label for name, meta, kind in user_settings(IN_SCENE) if kind is not bool}
    long = [name for name in advanced if len(labels.get(name, "")) > LABEL_CHARS]
    assert long and all(advanced[advanced.index(name) - 1] == labels[name] for name in long)
    assert all(len(text) <= LINE_CHARS for text in advanced if text.startswith("Uses "))
    assert " ".join(draw_panel(result.VIEW3D_PT_gt2gs_result, context)) == result.NO_RUN_TEXT  # across the panel
    context.scene.gt2gs.texture_path = ""  # no texture: Transfer disabled, and the panel says why
    view = transfer_panel.current_view(context)
    assert not view.can_transfer and view.message == "Not ready: blob"
    assert view.warnings == ["Choose a texture file (or an image) first"]
    assert "Choose a texture file (or an" in draw_panel(transfer_panel.VIEW3D_PT_gt2gs_transfer, context)


def test_every_choice_and_number_reads_well(fresh):
    """Every menu item has a tooltip, and numbers show 2 or 3 decimals (not 1.5000, 12.0000)."""
    from gt2gs_blender.panels.preferences import GT2GS_AP_preferences

    owners = (fresh.context.scene.gt2gs.bl_rna, GT2GS_AP_preferences.bl_rna)
    for prop in (p for owner in owners for p in owner.properties if not p.identifier.startswith(("rna_", "bl_"))):
        assert prop.description, prop.identifier
        if prop.type == "ENUM":
            assert all(item.description for item in prop.enum_items), prop.identifier
        if prop.type == "FLOAT":
            assert prop.precision in (2, 3), (prop.identifier, prop.precision)
            if prop.subtype != "ANGLE":  # one arrow click stays within the useful range's tenth (0.01 the finest)
                assert prop.step / 100 <= max(prop.soft_max / 10, 0.01), (prop.identifier, prop.step, prop.soft_max)


def test_up_axis_auto_follows_an_object_the_artist_stood_upright(blob):
    """A trainer's capture turned a quarter about X to stand in Blender: its own +Y is up for the run (also when a
    script names a preset); an Up Axis the artist chose stays; an object turned about Z alone leaves it to the
    splats."""
    blob.rotation_euler = (math.pi / 2, 0.0, 0.0)
    bpy.context.view_layer.update()
    assert transfer_run.with_object_up({"up": "auto"}, blob)["up"] == "+y"
    assert transfer_run.with_object_up({}, blob)["up"] == "+y"
    assert transfer_run.with_object_up({"up": "-x"}, blob)["up"] == "-x"
    blob.rotation_euler = (0.0, 0.0, 0.5)
    bpy.context.view_layer.update()
    assert transfer_run.with_object_up({"up": "auto"}, blob) == {"up": "auto"}
