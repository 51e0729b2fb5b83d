"""bench/recognise_scenes.py's exact surface, the ceiling the keep rules are judged against: it must cover the
pixels a result is judged on (the measure's alpha threshold), at the surface's own depth and colour, and lay the
texture the run lays (softened), or the ceiling is measured on other pixels than the results are."""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))

import recognise
import recognise_measure as measure
import recognise_scenes as scenes

from gt2gs_blender.core.cameras.warp import expected_depth
from gt2gs_blender.core.transfer.orientation_preview import laid_out_start
from gt2gs_blender.core.transfer.presets import preset
from gt2gs_blender.core.transfer.tone import LUMA
from gt2gs_blender.core.transfer.views import ViewSet


def test_measured_views_are_opaque_exactly_where_the_measure_counts_at_the_same_depth_and_colour():
    alpha = torch.tensor([[0.2, 0.5, 0.51], [0.7, 0.95, 1.0]])
    colour = torch.tensor([0.2, 0.4, 0.8])
    z = torch.tensor([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]])
    views = ViewSet(
        cameras=[],
        premultiplied=[alpha[..., None] * colour],
        alphas=[alpha],
        depths=[alpha * z],
        background=torch.zeros(3),
    )
    out = scenes.measured(views)
    counted = alpha > measure.MASK_ALPHA
    assert torch.equal(out.alphas[0], counted.float())
    assert torch.allclose(expected_depth(out.depths[0], out.alphas[0], 0.9)[counted], z[counted])
    assert torch.allclose(out.premultiplied[0][counted], colour.expand(int(counted.sum()), 3))
    assert not out.premultiplied[0][~counted].any() and not out.depths[0][~counted].any()


TEXTURE = ROOT.parent / "shared" / "data" / "textures" / "brick_wall.jpg"
needs_donut = pytest.mark.skipif(not scenes.DONUT.is_file() or not TEXTURE.is_file(), reason="needs ../shared")


def _small_donut_run(**overrides) -> tuple[scenes.BenchScene, object]:
    """The donut bench scene at 96 px with two held-out views, and a 4-view ``fast`` run's start on it."""
    bench = scenes.load_bench_scene("donut", resolution=96)
    bench = replace(bench, held_out=bench.held_out[:2])
    config = preset("fast", background=bench.background, resolution=96, n_views=4, **overrides)
    return bench, scenes.run_start(bench, config, TEXTURE)


@needs_donut
def test_the_surface_covers_every_pixel_a_result_is_judged_on():
    bench, run = _small_donut_run()
    surface = scenes.layout_surface(run, bench, TEXTURE)
    for (_, coverage), (_, alpha) in zip(surface, recognise.held_out_renders(bench.scene, bench), strict=True):
        counted = alpha > measure.MASK_ALPHA
        assert (alpha[counted] < 0.9).any()  # the semi-transparent rim the layout's own surface leaves out
        np.testing.assert_array_equal(coverage > measure.MASK_ALPHA, counted)


@needs_donut
def test_the_bench_start_is_the_runs_start_with_the_texture_softened():
    _, run = _small_donut_run(texture_softness=0.05)
    bench_start = scenes.layout_start(run, TEXTURE)
    assert torch.allclose(bench_start.base_colors, laid_out_start(run).base_colors)


@needs_donut
def test_the_target_with_nothing_of_the_scene_kept_is_the_surface():
    bench, run = _small_donut_run(keep_scene=0.0, scene_colour=0.0, scene_brightness=0.0)
    target = scenes.layout_surface(run, bench, TEXTURE, shaded=True)
    for (shaded, _), (plain, _) in zip(target, scenes.layout_surface(run, bench, TEXTURE), strict=True):
        np.testing.assert_array_equal(shaded, plain)


def _luma_correlation(image: np.ndarray, reference: np.ndarray, counted: np.ndarray) -> float:
    """Pearson correlation of two uint8 RGB images' luminance over the ``counted`` pixels."""
    luma = np.asarray(LUMA)
    return float(np.corrcoef((image @ luma)[counted], (reference @ luma)[counted])[0, 1])


@needs_donut
def test_the_target_keeps_the_scenes_light_and_dark_where_the_surface_does_not():
    bench, run = _small_donut_run()
    originals = recognise.held_out_renders(bench.scene, bench)
    target = scenes.layout_surface(run, bench, TEXTURE, shaded=True)
    surface = scenes.layout_surface(run, bench, TEXTURE)
    for (kept, _), (plain, _), (original, alpha) in zip(target, surface, originals, strict=True):
        counted = alpha > measure.MASK_ALPHA
        # measured: 0.92 / 0.90 against 0.01 / -0.03
        assert _luma_correlation(kept, original, counted) > _luma_correlation(plain, original, counted) + 0.5
