"""bench/recognise.py's calibration must show the measure the texture alone: the projected rows lay the photo with
nothing of the scene's light or colour (from Keep Scene on, b564119, they shaded it by the scene's full luminance,
and the fern's leaves outvoted the texture under the Gabor measure: 2 of 6 found instead of 6), and a run with the
layout off is compared with the sketch its own preview shows."""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))

import recognise
import recognise_scenes as scenes

from gt2gs_blender.core.transfer.orientation_preview import show
from gt2gs_blender.core.transfer.presets import preset

TEXTURE = ROOT.parent / "shared" / "data" / "textures" / "brick_wall.jpg"
needs_donut = pytest.mark.skipif(not scenes.DONUT.is_file() or not TEXTURE.is_file(), reason="needs ../shared")


def _donut(resolution: int = 96) -> scenes.BenchScene:
    bench = scenes.load_bench_scene("donut", resolution=resolution)
    return replace(bench, held_out=bench.held_out[:2])


def _recoloured(bench: scenes.BenchScene) -> scenes.BenchScene:
    """The same splats in other colours: the base colours mirrored about grey, no view-dependent colour."""
    scene = bench.scene
    return replace(bench, scene=replace(scene, sh_dc=-scene.sh_dc, sh_rest=torch.zeros_like(scene.sh_rest)))


@needs_donut
def test_the_projected_calibration_lays_the_texture_alone_whatever_the_scenes_colours():
    bench = _donut()
    other = _recoloured(bench)
    config = preset("fast", background=bench.background, resolution=96)
    alphas = [alpha for _, alpha in recognise.held_out_renders(bench.scene, bench)]
    for (a, _), (b, _) in zip(
        recognise.projected(bench, TEXTURE, 32, config, alphas),
        recognise.projected(other, TEXTURE, 32, config, alphas),
        strict=True,
    ):
        assert a.std() > 10  # the brick is there
        np.testing.assert_array_equal(a, b)


@needs_donut
def test_a_layout_off_run_is_compared_with_the_sketch_its_preview_shows():
    bench = _donut()
    other = _recoloured(bench)
    config = preset("fast", background=bench.background, resolution=96, n_views=4, layout=False)
    runs = [scenes.run_start(b, config, TEXTURE) for b in (bench, other)]
    alphas = [alpha for _, alpha in recognise.held_out_renders(bench.scene, bench)]
    first = [recognise.sketched(run, b, TEXTURE, alphas)[0][0] for run, b in zip(runs, (bench, other), strict=True)]
    assert np.abs(first[0].astype(int) - first[1].astype(int)).max() > 40  # the sketch keeps the scene's light
    cam = bench.held_out[0]
    framed = cam.scaled(runs[0].config.resolution / max(cam.width, cam.height))  # as the run frames its views
    shown = show(replace(runs[0], cameras=[framed]), size=max(cam.width, cam.height)).image
    np.testing.assert_array_equal(first[0], shown)


def test_colour_specks_count_dots_of_another_hue_and_not_light_and_dark():
    """The bench's colour-noise measure: a flat image has none; 9 isolated magenta dots on grey are 9 / the object's
    pixels; the same dots in dark grey (a texture's dark gaps) are none; pixels off the object do not count."""
    grey = np.full((60, 60, 3), 128, np.uint8)
    alpha = np.ones((60, 60), np.float32)
    assert recognise.colour_specks([(grey, alpha)], [(grey, alpha)]) == 0.0
    dots = (slice(10, 50, 15), slice(10, 50, 15))  # a 3 x 3 lattice of single pixels
    magenta, dark = grey.copy(), grey.copy()
    magenta[dots] = (170, 90, 150)
    dark[dots] = (60, 60, 60)
    assert recognise.colour_specks([(magenta, alpha)], [(grey, alpha)]) == pytest.approx(9 / 3600)
    assert recognise.colour_specks([(dark, alpha)], [(grey, alpha)]) == 0.0
    half = alpha.copy()
    half[:, 30:] = 0.0  # the object's left half holds 6 of the dots (columns 10 and 25)
    assert recognise.colour_specks([(magenta, alpha)], [(grey, half)]) == pytest.approx(6 / 1800)


def test_accent_shift_is_how_far_small_vivid_features_moved_in_colour():
    """The bench's accent measure: blue dots on grey (a robot's eyes) kept are 0; turned grey, the shift is the blue's
    Lab (a, b) distance from grey (OpenCV's Lab, the oracle); a large blue half is no small feature: with none, NaN."""
    grey = np.full((60, 60, 3), 128, np.uint8)
    alpha = np.ones((60, 60), np.float32)
    dots = (slice(10, 50, 15), slice(10, 50, 15))
    blue = grey.copy()
    blue[dots] = (40, 60, 220)
    assert recognise.accent_shift([(blue, alpha)], [(blue, alpha)]) == 0.0
    lab = cv2.cvtColor(np.array([[[40, 60, 220], [128, 128, 128]]], np.float32) / 255.0, cv2.COLOR_RGB2Lab)[0, :, 1:]
    assert recognise.accent_shift([(grey, alpha)], [(blue, alpha)]) == pytest.approx(np.linalg.norm(lab[0] - lab[1]))
    halves = grey.copy()
    halves[:, 30:] = (40, 60, 220)
    shifted = halves.copy()
    shifted[:, 30:] = 128
    assert np.isnan(recognise.accent_shift([(shifted, alpha)], [(halves, alpha)]))  # each pixel like its neighbours
    assert np.isnan(recognise.accent_shift([(grey, alpha)], [(grey, alpha)]))


def test_hue_drift_is_the_hue_the_steps_added_over_the_object_and_not_its_light():
    """The bench's hue drift: a result the same as its start is 0; one whose object half turned from amber to pink is
    that (a, b) distance (cv2's Lab of the two colours) within 1 % (the column at the seam blurs into the backdrop),
    the backdrop itself never counted; a stripe pattern finer than the blur, in its start's hues, counts for little."""
    alpha = np.zeros((64, 128), np.float32)
    alpha[:, :64] = 1.0
    start = np.full((64, 128, 3), (190, 150, 90), np.uint8)
    start[:, 64:] = (20, 200, 20)  # the backdrop: never counted, whatever it does
    pink = start.copy()
    pink[:, :64], pink[:, 64:] = (200, 120, 150), (200, 20, 200)
    lab = cv2.cvtColor(np.array([[[190, 150, 90], [200, 120, 150]]], np.float32) / 255.0, cv2.COLOR_RGB2Lab)[0, :, 1:]
    assert recognise.hue_drift([(start, alpha)], [(start, alpha)], [(start, alpha)]) == 0.0
    drift = recognise.hue_drift([(pink, alpha)], [(start, alpha)], [(start, alpha)])
    assert drift == pytest.approx(float(np.linalg.norm(lab[0] - lab[1])), rel=0.01)
    fine = start.copy()
    fine[:, :64:2] = (170, 134, 80)  # the start's own hue, darker, every other column
    assert recognise.hue_drift([(fine, alpha)], [(start, alpha)], [(start, alpha)]) < 0.1 * drift


def test_own_hue_forgives_a_drift_back_toward_the_capture_and_counts_one_off_the_way():
    """The bench's own hue: a result between its start (amber) and the original (red) at a third of the way, or at the
    original itself, is 0 (a drift the layout term allows for free) while ``hue_drift`` counts it; a result as far
    past the start on the other side of the way (green) is its whole distance from the start, as ``hue_drift``'s."""
    alpha = np.ones((48, 48), np.float32)
    colours = {"start": (190, 150, 90), "original": (200, 60, 50), "green": (120, 190, 90)}
    lab = {k: cv2.cvtColor(np.array([[v]], np.float32) / 255.0, cv2.COLOR_RGB2Lab)[0, 0] for k, v in colours.items()}
    start, original = (np.full((48, 48, 3), colours[k], np.uint8) for k in ("start", "original"))
    third = cv2.cvtColor((lab["start"] + (lab["original"] - lab["start"]) / 3)[None, None], cv2.COLOR_Lab2RGB)
    between = np.full((48, 48, 3), np.rint(255.0 * third[0, 0]), np.uint8)  # a third of the way in Lab, not in RGB
    for result in (between, original):
        assert recognise.own_hue([(result, alpha)], [(start, alpha)], [(original, alpha)]) < 0.5
        assert recognise.hue_drift([(result, alpha)], [(start, alpha)], [(original, alpha)]) > 5.0
    away = lab["start"][1:] - lab["green"][1:]
    assert float(np.dot(away, lab["original"][1:] - lab["start"][1:])) > 0  # green lies behind the start, off the way
    green = np.full((48, 48, 3), colours["green"], np.uint8)
    own = recognise.own_hue([(green, alpha)], [(start, alpha)], [(original, alpha)])
    assert own == pytest.approx(float(np.linalg.norm(away)), rel=0.01)


def test_part_hues_keep_parts_apart_whatever_tint_the_whole_takes():
    """The bench's part-hue measure: a pink and a beige half of like light (icing on dough) kept are 1, and 1 still
    under a tint over the whole; both halves one hue is near 0 (the floor's share alone); the hues swapped is
    below 0; a scene of one hue has nothing to keep, so any one hue scores 1."""
    alpha = np.ones((60, 80), np.float32)
    two = np.empty((60, 80, 3), np.uint8)
    two[:, :40], two[:, 40:] = (200, 140, 150), (190, 160, 120)
    tinted = np.clip(two.astype(int) + np.array([-20, 0, 25]), 0, 255).astype(np.uint8)
    one, swapped = np.full_like(two, (195, 150, 135)), two[:, ::-1].copy()
    assert recognise.part_hues([(two, alpha)], [(two, alpha)]) == pytest.approx(1.0)
    assert recognise.part_hues([(tinted, alpha)], [(two, alpha)]) > 0.97
    assert 0.0 < recognise.part_hues([(one, alpha)], [(two, alpha)]) < 0.05
    assert recognise.part_hues([(swapped, alpha)], [(two, alpha)]) < -0.9
    plain = np.full_like(two, 128)
    assert recognise.part_hues([(one, alpha)], [(plain, alpha)]) == pytest.approx(1.0)
