"""Parts in Blender: Find Parts on a splat object of two touching boxes of unlike colour, Select Part, the run and
the orientation preview restyling only the selected part, and the list marked stale once the object changes."""

from __future__ import annotations

import numpy as np
import pytest

bpy = pytest.importorskip("bpy", exc_type=ModuleNotFoundError)

from gt2gs_blender.app.images import write_png
from gt2gs_blender.blender import parts, splats, transfer_run
from gt2gs_blender.blender.job import DONE
from gt2gs_blender.core.scene.arrays import SplatArrays
from gt2gs_blender.core.scene.inria import SH_C0
from gt2gs_blender.core.scene.ply_write import write_ply
from gt2gs_blender.panels.parts import NO_PARTS_TEXT, GT2GS_UL_parts, VIEW3D_PT_gt2gs_parts
from gt2gs_blender.panels.sidebar import LINE_CHARS

from ..worker_tools import colours_differ, stripes
from .test_transfer_ui import RecordingLayout, dc, draw_panel, private_temp, tick_until  # noqa: F401 (private_temp: the jobs' own folder)

pytestmark = pytest.mark.blender

BODY, STAND = 600, 300
BODY_RGB, STAND_RGB = (0.85, 0.7, 0.4), (0.08, 0.08, 0.1)


def two_boxes() -> SplatArrays:
    """A light body (600 splats) standing on a dark stand (300) that it touches along a face."""
    rng = np.random.default_rng(0)
    means = np.concatenate(
        [rng.uniform([0, 0, 0], [1, 1, 1], (BODY, 3)), rng.uniform([0, 0, -0.5], [1, 1, 0], (STAND, 3))]
    )
    colours = np.repeat([BODY_RGB, STAND_RGB], [BODY, STAND], axis=0) + rng.normal(scale=0.02, size=(BODY + STAND, 3))
    n = len(means)
    return SplatArrays(
        means=means.astype(np.float32),
        quats=np.tile(np.float32([1, 0, 0, 0]), (n, 1)),
        log_scales=np.full((n, 3), np.log(0.03), np.float32),
        opacity_logits=np.full(n, np.log(0.9 / 0.1), np.float32),
        sh_dc=((np.clip(colours, 0, 1) - 0.5) / SH_C0).astype(np.float32),
        sh_rest=np.zeros((n, 0, 3), np.float32),
        extras={},
    )


@pytest.fixture
def boxes(fresh, tmp_path):
    """The two boxes imported as the active splat object, with a stripe texture and small, fast settings."""
    ply, texture = tmp_path / "guitar.ply", tmp_path / "stripes.png"
    write_ply(ply, two_boxes())
    write_png(texture, (stripes() * 255).astype(np.uint8))
    assert fresh.ops.gt2gs.import_ply(filepath=str(ply)) == {"FINISHED"}
    settings = fresh.context.scene.gt2gs
    settings.texture_path = str(texture)
    settings.preset = "preview"
    settings.stylise_steps, settings.resolution, settings.n_angles, settings.n_views = 6, 48, 4, 2
    yield fresh.context.active_object
    for run in list(transfer_run.ACTIVE.values()):
        run.cancel()
        run.finish()
    transfer_run.OUTCOMES.clear()


def test_find_parts_lists_the_two_boxes_with_their_counts_and_colours(boxes):
    store = bpy.context.scene.gt2gs_parts
    assert not bpy.ops.gt2gs.select_part.poll()  # nothing to select before Find Parts
    before = draw_panel(VIEW3D_PT_gt2gs_parts, bpy.context)
    assert before[0] == "gt2gs.find_parts" and " ".join(before[1:]) == NO_PARTS_TEXT
    assert bpy.ops.gt2gs.find_parts() == {"FINISHED"}
    assert draw_panel(VIEW3D_PT_gt2gs_parts, bpy.context) == [
        "gt2gs.find_parts",
        "gt2gs.select_part",
        "gt2gs.select_whole_parts",
        "region_only",
    ]
    row: list = []
    GT2GS_UL_parts.draw_item(None, bpy.context, RecordingLayout(row), store, store.items[1], 0, store, "active")
    assert row == ["colour", "Part 1", f"{STAND} splats"]
    assert [(item.part, item.splats) for item in store.items] == [(0, BODY), (1, STAND)]
    body_linear = splats.srgb_to_linear(np.array(BODY_RGB))
    np.testing.assert_allclose(store.items[0].colour[:], body_linear, atol=0.02)  # the swatch is scene-linear
    assert store.object == boxes and store.point_count == BODY + STAND
    assert parts.stale_text(store, boxes) is None
    assert parts.LABEL_ATTRIBUTE not in splats.object_to_scene(boxes)[0].extras  # never exported


def test_select_part_selects_exactly_its_splats_and_restyles_only_them(boxes):
    bpy.ops.gt2gs.find_parts()
    assert not bpy.context.scene.gt2gs.region_only
    assert bpy.ops.gt2gs.select_part(part=1) == {"FINISHED"}
    np.testing.assert_array_equal(transfer_run.selected_points(boxes), np.arange(BODY, BODY + STAND))
    assert bpy.context.scene.gt2gs.region_only and boxes.mode == "EDIT"
    bpy.context.scene.gt2gs_parts.active = 0
    assert bpy.ops.gt2gs.select_part() == {"FINISHED"}  # the part picked in the list, replacing the selection
    np.testing.assert_array_equal(transfer_run.selected_points(boxes), np.arange(BODY))
    with pytest.raises(RuntimeError, match="parts 0 to 1"):
        bpy.ops.gt2gs.select_part(part=2)
    clicked = np.zeros(BODY + STAND, bool)
    clicked[BODY + 7] = True  # one splat of the stand, as a click in Edit Mode selects it
    boxes.data.attributes[transfer_run.SELECTION_ATTRIBUTE].data.foreach_set("value", clicked)
    assert bpy.ops.gt2gs.select_whole_parts() == {"FINISHED"}
    np.testing.assert_array_equal(transfer_run.selected_points(boxes), np.arange(BODY, BODY + STAND))
    assert bpy.context.scene.gt2gs_parts.active == 1
    clicked[3] = True  # and one of the body: both parts
    boxes.data.attributes[transfer_run.SELECTION_ATTRIBUTE].data.foreach_set("value", clicked)
    assert bpy.ops.gt2gs.select_whole_parts() == {"FINISHED"}
    np.testing.assert_array_equal(transfer_run.selected_points(boxes), np.arange(BODY + STAND))
    assert bpy.ops.gt2gs.select_part(part=0) == {"FINISHED"}
    np.testing.assert_array_equal(transfer_run.selected_points(boxes), np.arange(BODY))
    assert bpy.ops.gt2gs.select_part(part=1, extend=True) == {"FINISHED"}  # Shift-click: both
    np.testing.assert_array_equal(transfer_run.selected_points(boxes), np.arange(BODY + STAND))
    assert bpy.ops.gt2gs.select_part(part=0) == {"FINISHED"}
    bpy.ops.object.mode_set(mode="OBJECT")
    bpy.context.scene.gt2gs.result_mode = "IN_PLACE"
    original = dc(boxes)
    run = transfer_run.TransferRun.start(bpy.context, {})
    assert tick_until(run, lambda s: s.finished).state == DONE
    run.finish()
    restyled = dc(boxes)  # the splats left alone first, then the restyled ones (split to the texture's detail)
    np.testing.assert_array_equal(restyled[:STAND], original[BODY:])  # the stand is untouched
    assert colours_differ(restyled[STAND:], original[:BODY])
    assert parts.stale_text(bpy.context.scene.gt2gs_parts, boxes) == "The object changed since: Find Parts again"
    with pytest.raises(RuntimeError, match="changed since"):
        bpy.ops.gt2gs.select_part(part=0)


def test_the_orientation_preview_shows_the_selected_part(boxes):
    """The preview lays the texture on the selected part only: the body's preview differs from the stand's."""
    bpy.ops.gt2gs.find_parts()
    frames = []
    for part in (0, 1):
        bpy.ops.gt2gs.select_part(part=part)
        run = transfer_run.TransferRun.start(bpy.context, {}, kind="preview")
        np.testing.assert_array_equal(
            np.load(run.job.path("region.npy")), np.flatnonzero(np.arange(900) // BODY == part)
        )
        assert tick_until(run, lambda s: s.finished).state == DONE
        run.finish()
        preview = transfer_run._previews["collection"][transfer_run.PREVIEW_KEY]
        pixels = np.empty(int(np.prod(preview.image_size)) * 4, np.float32)
        preview.image_pixels_float.foreach_get(pixels)
        frames.append(pixels)
    assert np.abs(frames[0] - frames[1]).mean() > 0.01


def test_parts_found_for_another_object_are_marked_stale(boxes, tmp_path):
    bpy.ops.gt2gs.find_parts()
    other = tmp_path / "other.ply"
    write_ply(other, two_boxes())
    assert bpy.ops.gt2gs.import_ply(filepath=str(other)) == {"FINISHED"}
    store, active = bpy.context.scene.gt2gs_parts, bpy.context.active_object
    assert parts.stale_text(store, active) == f"Found for {boxes.name!r}, not this object: Find Parts again"
    shown = draw_panel(VIEW3D_PT_gt2gs_parts, bpy.context)
    buttons = ["gt2gs.select_part", "gt2gs.select_whole_parts", "region_only"]
    assert shown[0] == "gt2gs.find_parts" and shown[-3:] == buttons
    assert " ".join(shown[1:-3]) == parts.stale_text(store, active)  # in lines that fit the sidebar
    assert all(len(text) <= LINE_CHARS for text in shown)
    with pytest.raises(RuntimeError, match="not this object"):
        bpy.ops.gt2gs.select_part(part=0)
    bpy.data.objects.remove(boxes)
    assert parts.stale_text(store, active) == "Found for an object that is gone: Find Parts again"
