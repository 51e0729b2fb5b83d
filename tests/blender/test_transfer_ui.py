"""The transfer from Blender: operators through bpy.ops, the worker/poll cycle of the modal operator
(driven by test ticks), cancel and crash, the panel's state function, preferences, views, batch script."""

from __future__ import annotations

import glob
import math
import os
import resource
import signal
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest

bpy = pytest.importorskip("bpy", exc_type=ModuleNotFoundError)

from gt2gs_blender.app import deps
from gt2gs_blender.app.images import write_png
from gt2gs_blender.blender import splats, transfer_run, views
from gt2gs_blender.blender.job import CANCELLED, DONE, ERROR, IDLE, RUNNING, JobStatus
from gt2gs_blender.blender.transfer_run import eta_text
from gt2gs_blender.core.cameras.cameras_json import load_cameras_json
from gt2gs_blender.core.errors import MEMORY_ADVICE
from gt2gs_blender.core.scene.ply_write import write_ply
from gt2gs_blender.panels.transfer_panel import transfer_view

from ..test_transfer import blob_scene, stripes
from ..test_worker import OUT_OF_MEMORY, address_space_cap, colours_differ, needs_prlimit
from .conftest import SHARED

pytestmark = pytest.mark.blender

TEXTURES = sorted(glob.glob(str(SHARED / "data" / "textures" / "*.jpg")))


@pytest.fixture
def inputs(tmp_path) -> dict[str, Path]:
    """A small splat scene and a stripe texture on disk."""
    ply, texture = tmp_path / "blob.ply", tmp_path / "stripes.png"
    write_ply(ply, blob_scene(600))
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
    view = transfer_view(blob.name, None, transfer_run.OUTCOMES["transfer"])
    assert view.state == DONE and dict(view.report_rows)["Result"] == "blob GT²"


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


def test_scene_cameras_become_views_in_object_space(fresh):
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
    settings.stylise_geometry, settings.depth_ratio, settings.object_backdrop = True, 2.0, True
    settings.background = (0.0, 0.5, 1.0)
    _, config = transfer_run.config_overrides(fresh.context, {})
    made = make_preset("balanced", **config)
    assert (made.stylise_steps, made.gpb, made.angle, made.texture_height) == (12, False, 15.0, 96)
    assert made.stylise_geometry and made.depth_ratio == 2.0 and made.object_backdrop
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
        "metrics": {"texture_match_start": 0.3, "texture_match": 0.2, "ssim": 0.81},
    }
    done = transfer_view("donut", None, transfer_run.Outcome(DONE, "done in 15 s", report, "donut GT²", 15.2))
    rows = dict(done.report_rows)
    assert done.state == DONE and done.message == "Done in 15 s" and done.progress is None
    assert rows["Time"] == "15 s (texture transfer 12 s)"  # the wait the user saw, beside the engine's part
    assert rows["Result"] == "donut GT²" and rows["Splats"] == "45,624" and rows["Views"] == "8 at 128×128"
    assert rows["Texture Match"] == "0.300 → 0.200" and rows["Features"] == "vgg19_norm_relu3"
    error = transfer_view("donut", None, transfer_run.Outcome(ERROR, "the worker process exited with status 1"))
    assert error.state == ERROR and error.icon == "ERROR" and error.can_transfer and not error.report_rows
    assert error.message == "Failed: the worker process exited with status 1"
    assert transfer_view("donut", None, transfer_run.Outcome(CANCELLED, "cancelled")).icon == "CANCEL"
    assert eta_text(None) == "" and eta_text(5) == "ETA 0:05"


def test_preferences_install_command_and_status(fresh):
    from gt2gs_blender.operators.dependencies import GT2GS_OT_install_dependencies, install_commands
    from gt2gs_blender.panels.preferences import GT2GS_AP_preferences, dependency_rows

    assert GT2GS_AP_preferences.bl_idname == "gt2gs_blender"
    commands = install_commands("CUDA", "/user/extensions/.user/gt2gs_blender/deps")
    assert commands[-1] == deps.install_command(sys.executable, "/user/extensions/.user/gt2gs_blender/deps", "CUDA")
    assert all(command[0] == sys.executable for command in commands)
    assert not GT2GS_OT_install_dependencies.poll(fresh.context)  # offline here, and not an installed extension
    rows = {module: ok for module, _, ok in dependency_rows(None)}
    assert rows == {"torch": True, "numpy": True, "cv2": True}


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
    assert "unknown preset 'ultra'" in capsys.readouterr().err


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
    from gt2gs_blender.core.transfer.config import IN_PREFERENCES, IN_SCENE, SETTINGS
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
