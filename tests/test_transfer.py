"""The texture-transfer pipeline end to end on small scenes: contract, determinism, cancel, progress."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import torch

from gt2gs_blender.core.cameras.generate import auto_views
from gt2gs_blender.core.progress import Cancelled
from gt2gs_blender.core.render import render
from gt2gs_blender.core.scene.gaussians import GaussianScene
from gt2gs_blender.core.transfer.bank import bank_depth_ratio
from gt2gs_blender.core.transfer.config import TransferConfig
from gt2gs_blender.core.transfer.pipeline import transfer
from gt2gs_blender.core.transfer.presets import PRESETS, preset
from gt2gs_blender.core.transfer.views import ViewSet

from .worker_tools import stripes


def blob_scene(n: int = 1500, seed: int = 0) -> GaussianScene:
    """A fuzzy coloured ball of Gaussians with an extra property, like a small real scene."""
    g = torch.Generator().manual_seed(seed)
    means = torch.randn(n, 3, generator=g) * 0.3
    scene = GaussianScene.from_activated(
        means,
        torch.full((n, 3), 0.04),
        torch.full((n,), 0.8),
        torch.rand(n, 3, generator=g) * 0.5 + 0.25,
        quats=torch.randn(n, 4, generator=g),
        sh_degree=1,
    )
    scene.extras = {"confidence": np.arange(n, dtype=np.float32)}
    return scene


def tiny(**overrides) -> TransferConfig:
    base = dict(
        resolution=48,
        n_views=3,
        stylise_steps=4,
        n_scales=2,
        n_angles=4,
        texture_height=96,
        evaluate=False,
        cache_dir=None,
        preview_every=2,
        gpb=False,
        densify=False,
    )
    base.update(overrides)
    return TransferConfig(**base)


@pytest.fixture
def cache(tmp_path):
    return str(tmp_path / "banks")


def test_transfer_contract(cache):
    scene = blob_scene()
    before = {k: v.clone() for k, v in scene.tensors().items()}
    result = transfer(scene, stripes(), None, tiny(cache_dir=cache))
    assert all(torch.equal(before[k], v) for k, v in scene.tensors().items())  # input untouched
    out = result.scene
    assert len(out) == len(scene) and out.sh_degree == 0
    assert torch.equal(out.means, scene.means) and torch.equal(out.log_scales, scene.log_scales)
    assert not torch.allclose(out.sh_dc, scene.sh_dc)  # colours changed
    assert np.array_equal(out.extras["confidence"], scene.extras["confidence"])
    assert torch.isfinite(out.sh_dc).all()
    report = result.report
    assert report["n_gaussians"] == len(scene) and report["n_views"] == 3
    assert set(report["stage_seconds"]) == {"prepare", "bank", "stylise", "finish"}
    assert "fallback" in report["weights"] and report["weights"]["reason"]
    # what was asked, and what ran: the automatic values resolved, nothing else changed
    asked, ran, resolved = report["asked"], report["config"], report["resolved"]
    assert asked == tiny(cache_dir=cache).to_dict()
    assert {k for k in asked if asked[k] != ran[k]} <= set(resolved) and all(ran[k] == v for k, v in resolved.items())
    assert asked["stylise_geometry"] == "auto" and resolved["stylise_geometry"] in ("on", "off")
    assert resolved["layout_projection"] in ("box", "view") and resolved["depth_ratio"] >= 1.0


def test_transfer_is_deterministic(cache):
    a = transfer(blob_scene(), stripes(), None, tiny(cache_dir=cache)).scene
    b = transfer(blob_scene(), stripes(), None, tiny(cache_dir=cache)).scene
    assert torch.equal(a.sh_dc, b.sh_dc)


def test_stylised_sh_degree_trains_view_dependent_bands(cache):
    """Degree 0 (default): rest bands dropped. Degree 2: zero-padded bands are trained, so the restyled
    colour of a Gaussian changes with the direction it is seen from."""
    scene = blob_scene()
    flat = transfer(scene, stripes(), None, tiny(cache_dir=cache)).scene
    shaded = transfer(scene, stripes(), None, tiny(cache_dir=cache, stylised_sh_degree=2)).scene
    assert flat.sh_degree == 0 and shaded.sh_degree == 2
    assert torch.isfinite(shaded.sh_rest).all() and shaded.sh_rest.abs().amax() > 1e-4
    with pytest.raises(ValueError, match="stylised_sh_degree"):
        tiny(stylised_sh_degree=4)


def test_progress_is_monotone_with_previews(cache):
    seen = []
    transfer(blob_scene(), stripes(), None, tiny(cache_dir=cache), progress=seen.append)
    fractions = [p.fraction for p in seen]
    assert fractions == sorted(fractions) and fractions[-1] == 1.0
    assert {p.stage for p in seen} == {"prepare", "bank", "stylise", "finish"}
    previews = [p.preview for p in seen if p.preview is not None]
    assert previews and previews[0].shape == (48, 48, 3) and previews[0].dtype == np.uint8


def test_cancel_stops_the_run(cache):
    calls = {"n": 0}

    def cancel() -> bool:
        calls["n"] += 1
        return calls["n"] > 3

    scene = blob_scene()
    before = scene.sh_dc.clone()
    with pytest.raises(Cancelled):
        transfer(scene, stripes(), None, tiny(cache_dir=cache, stylise_steps=50), cancel=cancel)
    assert torch.equal(scene.sh_dc, before)


def test_stylisation_moves_renders_toward_the_texture(cache):
    """More steps, lower texture match (the NNFM objective itself), and content stays recognisable."""
    config = tiny(cache_dir=cache, stylise_steps=40, evaluate=True, resolution=64)
    metrics = transfer(blob_scene(), stripes(), None, config).report["metrics"]
    assert metrics["texture_match"] < metrics["texture_match_start"]
    assert metrics["ssim"] > 0.2


def test_presets_and_overrides():
    assert set(PRESETS) >= {"preview", "fast", "balanced"}
    assert preset("fast", stylise_steps=7).stylise_steps == 7
    assert preset("fast", stylise_steps=None) == PRESETS["fast"]
    with pytest.raises(ValueError, match="unknown preset"):
        preset("ultra")
    with pytest.raises(ValueError, match="unknown transfer settings"):
        preset("fast", colour=1)
    with pytest.raises(ValueError):
        TransferConfig(resolution=0)


@pytest.mark.slow
def test_fast_preset_on_the_shared_donut(shared, tmp_path):
    """Issue 4's acceptance: the real donut with a real texture and the real VGG-19 features, fast preset.

    texture_match (covered cells only) falls by at least 30 % from the colour-transferred start and
    the content stays recognisable (SSIM to the original renders >= 0.3). The method as the paper
    starts it: the layout's term holds the laid-out texture against this loss (tests/test_layout.py)."""
    from gt2gs_blender.core.scene.ply import read_ply

    scene = read_ply(shared / "data" / "scenes" / "donut" / "point_cloud.ply")
    config = preset(
        "fast",
        layout=False,
        texture_repeats=0.0,
        weights_path=str(shared / "weights"),
        cache_dir=str(tmp_path / "banks"),
    )
    report = transfer(scene, shared / "data" / "textures" / "herringbone_wood.jpg", None, config).report
    metrics = report["metrics"]
    assert report["weights"]["fallback"] is False
    assert metrics["texture_match"] <= 0.7 * metrics["texture_match_start"]
    assert metrics["ssim"] >= 0.3
    assert metrics["lt_lpips"] is not None and np.isfinite(metrics["lt_rmse"])


def test_threads_cap_the_run_and_are_restored(cache):
    """``threads`` sets torch's (and the C++ rasterizer's) thread count while the run works, then puts it back."""
    before = torch.get_num_threads()
    seen = []
    transfer(
        blob_scene(),
        stripes(),
        None,
        tiny(cache_dir=cache, threads=1),
        progress=lambda p: seen.append(torch.get_num_threads()),
    )
    assert seen and set(seen) == {1}
    assert torch.get_num_threads() == before
    with pytest.raises(ValueError, match="threads"):
        tiny(threads=-1)


def test_without_gt2_the_loss_is_plain_nnfm_on_the_textures_own_feature_map(cache):
    """--no-gt2 matches the texture's feature map as it is (paper Eq. 1), and still reports the texture
    match against the labelled bank, so the variants compare."""
    texture = stripes()
    nnfm = transfer(blob_scene(), texture, None, tiny(cache_dir=cache, gt2=False, evaluate=True, depth_ratio=2.0))
    gt2 = transfer(blob_scene(), texture, None, tiny(cache_dir=cache, evaluate=True, depth_ratio=2.0))
    assert nnfm.report["bank"] == {"features": 24 * 24, "scales": [1.0], "angles": 1}  # 96 px at stride 4
    assert gt2.report["bank"]["angles"] == 4 and gt2.report["bank"]["scales"] == [1.0, 0.5]
    assert nnfm.report["metrics"]["texture_match_start"] == pytest.approx(gt2.report["metrics"]["texture_match_start"])
    assert not torch.equal(nnfm.scene.sh_dc, gt2.scene.sh_dc)


@pytest.mark.parametrize("near, far, expected", [(2.0, 3.0, 2.875 / 2.125), (1.0, 5.0, 2.0)])
def test_bank_depth_ratio_is_the_views_own_up_to_the_cap(near, far, expected):
    """The bank's far/near ratio is measured over all views together (paper: Z_1/Z_k), capped at the
    authors' 2 for deep scenes, rounded to 0.01; a configured ratio wins."""
    depths = [torch.linspace(near, (near + far) / 2, 64).reshape(8, 8), torch.linspace(near, far, 64).reshape(8, 8)]
    views = ViewSet([], [torch.zeros(8, 8, 3)] * 2, [torch.ones(8, 8)] * 2, depths, torch.ones(3))
    assert bank_depth_ratio(views, TransferConfig()) == pytest.approx(round(expected, 2))
    assert bank_depth_ratio(views, TransferConfig(depth_ratio=3.0)) == 3.0
    assert bank_depth_ratio(views, TransferConfig(n_scales=1)) == 1.0
    with pytest.raises(ValueError, match="depth_ratio"):
        TransferConfig(depth_ratio=0.5)


def test_object_colour_is_the_mean_of_covered_pixels():
    """The stylise backdrop: the un-premultiplied colour of pixels over the alpha threshold, all views
    together; with nothing covered, the background."""
    alphas = [torch.tensor([[1.0, 0.95], [0.5, 0.0]]), torch.tensor([[0.92, 0.0], [0.0, 0.0]])]
    colours = [
        torch.tensor([[[0.2, 0.4, 0.6], [0.4, 0.4, 0.4]], [[1.0, 1.0, 1.0], [0.0, 0.0, 0.0]]]),
        torch.tensor([[[0.6, 0.1, 0.2], [0.0, 0.0, 0.0]], [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]]),
    ]
    premultiplied = [c * a[..., None] for c, a in zip(colours, alphas)]
    views = ViewSet([], premultiplied, alphas, [torch.ones(2, 2)] * 2, torch.ones(3))
    expected = torch.tensor([[0.2, 0.4, 0.6], [0.4, 0.4, 0.4], [0.6, 0.1, 0.2]]).mean(0)
    assert torch.allclose(views.object_colour(), expected, atol=1e-6)
    assert torch.allclose(views.composited(0, expected)[1, 1], expected)
    assert torch.equal(views.composited(0)[1, 1], torch.ones(3))
    empty = ViewSet([], [torch.zeros(2, 2, 3)], [torch.zeros(2, 2)], [torch.ones(2, 2)], torch.tensor([0.0, 0.5, 1.0]))
    assert torch.equal(empty.object_colour(), torch.tensor([0.0, 0.5, 1.0]))


def test_a_shallow_scene_gets_its_own_bank_scales(cache):
    """The blob seen from around it spans far less than twice its nearest depth: the bank's scales
    follow the measured ratio, not the authors' fixed 2."""
    report = transfer(blob_scene(), stripes(), None, tiny(cache_dir=cache)).report
    scales = report["bank"]["scales"]
    assert 0.5 < scales[-1] < 0.95 and scales[0] == 1.0


def test_cell_coverage_changes_what_the_loss_counts_not_the_metric(cache):
    """``cell_coverage`` 1 keeps silhouette cells out of the texture loss; the texture match (of the start
    and the result) is still measured on the metric's own covered cells, so the runs compare."""
    half = transfer(blob_scene(), stripes(), None, tiny(cache_dir=cache, evaluate=True))
    whole = transfer(blob_scene(), stripes(), None, tiny(cache_dir=cache, evaluate=True, cell_coverage=1.0))
    assert half.report["metrics"]["texture_match_start"] == whole.report["metrics"]["texture_match_start"]
    assert not torch.equal(half.scene.sh_dc, whole.scene.sh_dc)
    with pytest.raises(ValueError, match="cell_coverage"):
        tiny(cell_coverage=1.5)


LAID_OUT_START = dict(layout=True, texture_repeats=1.5, stylise_steps=0, correct_steps=0, color_transfer=False)
"""A run that only lays the texture out: its result is the optimisation's start."""


def test_laid_out_start_is_deterministic(cache):
    """The same scene lays out the same (splats no view sees take their nearest seen splat's normal:
    FLANN's randomised forest gave ~15 % of the blob's splats another neighbour, and colour, each run)."""
    a = transfer(blob_scene(), stripes(), None, tiny(cache_dir=cache, **LAID_OUT_START)).scene
    b = transfer(blob_scene(), stripes(), None, tiny(cache_dir=cache, **LAID_OUT_START)).scene
    assert torch.equal(a.sh_dc, b.sh_dc)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
def test_transfer_runs_on_cuda_as_on_the_cpu(cache):
    """The whole default path on the GPU (layout with shade, GT² prior links, AFCM, GPB, densification,
    skipped views, metrics, mixed precision; gsplat where installed): its laid-out start is the CPU's, and a
    short run ends with as many splats and finite colours measured as the same run on the CPU measures."""
    on_cpu = transfer(blob_scene(), stripes(), None, tiny(cache_dir=cache, device="cpu", **LAID_OUT_START)).scene
    on_gpu = transfer(blob_scene(), stripes(), None, tiny(cache_dir=cache, device="cuda", **LAID_OUT_START)).scene
    assert len(on_gpu) == len(on_cpu)
    differ = (on_gpu.sh_dc - on_cpu.sh_dc).abs().amax(dim=1)
    assert differ.mean() < 1e-3 and (differ > 0.01).float().mean() < 0.01  # a few normals may tip otherwise
    short = dict(layout=True, texture_repeats=1.5, stylise_steps=24, correct_steps=8, rounds=2, gpb=True)
    short.update(densify=True, densify_every=4, evaluate=True, resolution=64, cache_dir=cache)
    runs = {device: transfer(blob_scene(), stripes(), None, tiny(device=device, **short)) for device in ("cpu", "cuda")}
    gpu = runs["cuda"]
    assert gpu.report["device"].startswith("cuda") and torch.isfinite(gpu.scene.sh_dc).all()
    assert len(gpu.scene) == pytest.approx(len(runs["cpu"].scene), rel=0.03)  # densified alike, whichever backend
    for metric in ("texture_match", "ssim"):
        assert gpu.report["metrics"][metric] == pytest.approx(runs["cpu"].report["metrics"][metric], abs=0.03)


def in_units(scene: GaussianScene, factor: float) -> GaussianScene:
    """``scene`` with every length times ``factor``: the same capture saved in other units (cm instead of m)."""
    return replace(scene, means=scene.means * factor, log_scales=scene.log_scales + math.log(factor))


@pytest.mark.parametrize("geometry", ["off", "on"])
@pytest.mark.parametrize("factor", [100.0, 0.01])
def test_a_capture_in_other_units_is_textured_alike(cache, factor, geometry):
    """Captures come in metres, centimetres or a trainer's own units. The blob with every length times ``factor``
    (its automatic views scale with it) is laid out alike, but for a few splats whose normal tips on rounding, and
    its result, scaled back and seen from the same views, is the blob's own within float noise: an absolute length
    anywhere in the run (a threshold, an epsilon, a learning rate) would change the whole look."""
    config = tiny(
        cache_dir=cache,
        layout=True,
        texture_repeats=1.5,
        stylise_steps=12,
        correct_steps=4,
        rounds=2,
        stylise_geometry=geometry,
        resolution=64,
    )
    start = dict(stylise_steps=0, correct_steps=0)
    laid = transfer(blob_scene(), stripes(), None, replace(config, **start)).scene
    laid_scaled = transfer(in_units(blob_scene(), factor), stripes(), None, replace(config, **start)).scene
    differ = (laid_scaled.sh_dc - laid.sh_dc).abs().amax(dim=1)
    assert len(laid_scaled) == len(laid) and differ.mean() < 1e-3
    assert (differ > 0.01).float().mean() < 0.01  # a few splats' normals tip on rounding, as on the GPU
    ours = transfer(blob_scene(), stripes(), None, config).scene
    theirs = in_units(transfer(in_units(blob_scene(), factor), stripes(), None, config).scene, 1.0 / factor)
    cameras = auto_views(ours, 4, width=96, height=96)
    seen, seen_scaled = (render(s, cameras).colors for s in (ours, theirs))
    assert (seen - seen_scaled).abs().mean() < 4e-3  # 1.4e-3 measured; the texture 3 % larger: 0.015
    if geometry == "off":  # the splats split alike and stayed where they were split, in both units
        assert len(theirs) == len(ours) and torch.allclose(theirs.means, ours.means, atol=1e-5)
