"""Evaluation metrics: consistency by depth warping, texture match, SSIM, FPS, memory."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import torch

from gt2gs_blender.core.cameras.camera import Camera
from gt2gs_blender.core.features.extractor import FeatureExtractor
from gt2gs_blender.core.features.lpips import load_lpips
from gt2gs_blender.core.features.specs import VGG19_NORM_RELU3
from gt2gs_blender.core.features.weights import ResolvedWeights
from gt2gs_blender.core.render import render
from gt2gs_blender.core.scene.gaussians import GaussianScene
from gt2gs_blender.core.train.ssim import ssim
from gt2gs_blender.core.transfer import metrics

from .conftest import SHARED

W, H = 64, 48


@pytest.fixture(scope="module")
def lpips():
    if not (SHARED / "weights").is_dir():
        pytest.skip(f"shared weights not found at {SHARED / 'weights'}")
    return load_lpips(SHARED / "weights")


def still_views(count: int, step: float) -> tuple[torch.Tensor, ...]:
    """``count`` views from one camera of a flat wall; view k is the base image brightened by k*step."""
    g = torch.Generator().manual_seed(3)
    base = torch.nn.functional.interpolate(torch.rand(1, 3, 6, 8, generator=g), size=(H, W), mode="bilinear")
    base = 0.1 + 0.6 * base[0].permute(1, 2, 0)
    images = torch.stack([base + k * step for k in range(count)])
    cameras = [Camera(np.eye(4), 50.0, 50.0, W / 2, H / 2, W, H)] * count
    return images, torch.full((count, H, W), 3.0), torch.ones(count, H, W), cameras


def wall_scene(n: int = 50) -> GaussianScene:
    """A textured, opaque wall of n x n flat Gaussians on the plane z = 3."""
    coords = torch.linspace(-2.5, 2.5, n)
    y, x = torch.meshgrid(coords, coords, indexing="ij")
    means = torch.stack([x, y, torch.full_like(x, 3.0)], -1).reshape(-1, 3)
    spacing = float(coords[1] - coords[0])
    # little overlap, so little dependence on the per-view blending order of coplanar splats
    scales = torch.tensor([spacing * 0.5, spacing * 0.5, 1e-3]).expand(n * n, 3)
    colors = torch.stack(
        [
            0.5 + 0.4 * torch.sin(3 * means[:, 0]),
            0.5 + 0.4 * torch.cos(2 * means[:, 1]),
            0.5 + 0.2 * torch.sin(means[:, 0] + means[:, 1]),
        ],
        -1,
    )
    return GaussianScene.from_activated(means, scales, torch.full((n * n,), 0.98), colors)


def sliding_cameras(count: int) -> list[Camera]:
    """Cameras sliding sideways and turning slightly, looking at the wall."""
    cams = []
    for k in range(count):
        angle = 0.02 * k
        rot = np.array([[np.cos(angle), 0, np.sin(angle)], [0, 1, 0], [-np.sin(angle), 0, np.cos(angle)]])
        cams.append(Camera.from_cam_to_world(rot, [0.05 * k - 0.2, 0.0, 0.0], 80.0, 80.0, W / 2, H / 2, W, H))
    return cams


def test_identical_views_are_perfectly_consistent(lpips):
    images, depths, alphas, cameras = still_views(9, 0.0)
    for offset in (1, 7):
        scores = metrics.consistency(images, depths, alphas, cameras, offset, lpips=lpips)
        assert scores["rmse"] < 1e-6 and abs(scores["lpips"]) < 1e-6


def test_known_brightness_change_gives_known_rmse():
    images, depths, alphas, cameras = still_views(9, 0.02)
    assert metrics.consistency(images, depths, alphas, cameras, 1)["rmse"] == pytest.approx(0.02, abs=1e-6)
    assert metrics.consistency(images, depths, alphas, cameras, 7)["rmse"] == pytest.approx(0.14, abs=1e-6)
    assert metrics.consistency(images, depths, alphas, cameras, 9) == {"rmse": None, "lpips": None}


def test_invalid_pixels_are_left_out():
    images, depths, alphas, cameras = still_views(2, 0.0)
    images[1, :, : W // 2] = 1.0  # view 1 differs only where view 0 has no coverage
    alphas[0, :, : W // 2] = 0.0
    assert metrics.consistency(images, depths, alphas, cameras, 1)["rmse"] < 1e-6


def test_rendered_scene_is_consistent_and_noise_is_not(lpips):
    scene, cameras = wall_scene(), sliding_cameras(3)
    out = render(scene, cameras, backend="torch")
    assert out.alphas.min() > 0.8
    clean = metrics.consistency(out.colors, out.depths, out.alphas, cameras, 1, lpips=lpips)
    noisy = out.colors + 0.1 * torch.randn(out.colors.shape, generator=torch.Generator().manual_seed(1))
    dirty = metrics.consistency(noisy, out.depths, out.alphas, cameras, 1, lpips=lpips)
    assert clean["rmse"] < 0.02 and dirty["rmse"] > 0.09
    assert clean["lpips"] < 0.5 * dirty["lpips"]


def test_texture_match_equals_brute_force():
    g = torch.Generator().manual_seed(5)
    features, bank = torch.randn(300, 16, generator=g), torch.randn(70, 16, generator=g)
    f64, b64 = features.double(), bank.double()
    cosine = (f64 / f64.norm(dim=1, keepdim=True)) @ (b64 / b64.norm(dim=1, keepdim=True)).T
    expected = float((1 - cosine.max(dim=1).values).mean())
    assert metrics.texture_match(features, bank) == pytest.approx(expected, abs=1e-6)
    assert metrics.texture_match(features, bank, block_bytes=1000) == pytest.approx(expected, abs=1e-6)
    assert metrics.texture_match(bank, bank) == pytest.approx(0.0, abs=1e-6)


def test_evaluate_assembles_every_metric(lpips):
    scene, cameras = wall_scene(), sliding_cameras(8)
    out = render(scene, cameras, backend="torch")
    extractor = FeatureExtractor(VGG19_NORM_RELU3, ResolvedWeights(VGG19_NORM_RELU3, None, None, "test"))
    bank = extractor(out.colors[:1].permute(0, 3, 1, 2)).permute(0, 2, 3, 1).reshape(-1, extractor.spec.out_channels)
    both = (out.colors, out.colors, None)
    result = metrics.evaluate(
        out.colors, out.depths, out.alphas, cameras, both, lpips=lpips, extractor=extractor, bank_features=bank
    )
    assert set(result) == {"ssim", "st_rmse", "st_lpips", "lt_rmse", "lt_lpips", "texture_match"}
    assert result["ssim"] == pytest.approx(1.0, abs=1e-5)
    assert result["st_rmse"] < result["lt_rmse"] < 0.05 and result["st_lpips"] is not None
    assert 0.0 <= result["texture_match"] < 0.5
    assert metrics.evaluate(out.colors, out.depths, out.alphas, cameras, both)["texture_match"] is None


def test_texture_match_counts_only_covered_cells():
    """Background cells take no texture: the metric must equal the brute force over the covered cells."""
    scene, cameras = wall_scene(), sliding_cameras(2)
    out = render(scene, cameras, backend="torch")
    alphas = out.alphas.clone()
    alphas[:, :, alphas.shape[2] // 2 :] = 0.0  # pretend the right half is background
    extractor = FeatureExtractor(VGG19_NORM_RELU3, ResolvedWeights(VGG19_NORM_RELU3, None, None, "test"))
    bank = torch.randn(50, extractor.spec.out_channels, generator=torch.Generator().manual_seed(2))
    result = metrics.evaluate(
        out.colors,
        out.depths,
        alphas,
        cameras[:2],
        (out.colors, out.colors, None),
        extractor=extractor,
        bank_features=bank,
    )
    feats = extractor(out.colors.permute(0, 3, 1, 2))
    half = feats.shape[-1] // 2
    rows = feats[..., :half].permute(0, 2, 3, 1).reshape(-1, feats.shape[1])
    assert result["texture_match"] == pytest.approx(metrics.texture_match(rows, bank), abs=1e-6)


def test_peak_memory():
    memory = metrics.peak_memory_mib()
    assert memory["rss_peak_mib"] > 10 and memory["cuda_peak_mib"] is None


def paper_ssim(a: torch.Tensor, b: torch.Tensor) -> float:
    """The paper's whole-frame SSIM, mean over views (the reference implementation's)."""
    return float(ssim(a, b).mean())


def _photo(seed: int, size: int = 64) -> torch.Tensor:
    """A smooth random (size, size, 3) image in [0, 1] with detail at several scales."""
    g = np.random.default_rng(seed)
    coarse = cv2.resize(g.random((8, 8, 3)).astype(np.float32), (size, size), interpolation=cv2.INTER_CUBIC)
    return torch.from_numpy(np.clip(0.7 * coarse + 0.3 * g.random((size, size, 3)), 0.0, 1.0).astype(np.float32))


def rec709(images: torch.Tensor) -> torch.Tensor:
    """The Rec. 709 luminance (..., H, W, 1) of (..., H, W, 3) linear colours, written out here."""
    return (0.2126 * images[..., 0] + 0.7152 * images[..., 1] + 0.0722 * images[..., 2])[..., None]


def test_object_ssim_of_identical_renders_is_one_and_over_the_whole_frame_is_the_ssim_of_luminance():
    a, b = _photo(0)[None], _photo(1)[None]
    everywhere = torch.ones(1, 64, 64, dtype=torch.bool)
    assert metrics.object_ssim(a, a, everywhere) == pytest.approx(1.0, abs=1e-6)
    assert metrics.object_ssim(a, b, everywhere) == pytest.approx(paper_ssim(rec709(a), rec709(b)), abs=1e-6)
    assert metrics.object_ssim(a, b, torch.zeros(1, 64, 64, dtype=torch.bool)) is None


def test_a_new_colour_of_the_same_light_and_dark_keeps_the_scene_and_a_new_light_does_not():
    """Scene Kept judges the scene's light and dark, not the colour the texture gives it: the original's
    luminance in another hue scores 1, where the paper's colour-channel SSIM drops; the same hue with its light
    and dark changed scores low."""
    original = _photo(12)[None]
    y = rec709(original)
    tint = torch.tensor([1.2, 0.9, 1.1])
    recoloured = y * tint / float(rec709(tint[None, None]).squeeze())  # another hue, the same luminance
    relit = original * rec709(_photo(13)[None]) * 2.0
    everywhere = torch.ones(1, 64, 64, dtype=torch.bool)
    assert metrics.object_ssim(recoloured, original, everywhere) == pytest.approx(1.0, abs=1e-5)
    assert paper_ssim(recoloured, original) < 0.9
    assert metrics.object_ssim(relit, original, everywhere) < 0.75


def test_object_ssim_counts_only_the_objects_pixels():
    """A changed backdrop does not count; a changed object does, however small it is in the frame."""
    original = torch.ones(1, 64, 64, 3)
    original[0, 24:40, 24:40] = _photo(2, 16)
    covered = torch.zeros(1, 64, 64, dtype=torch.bool)
    covered[0, 24:40, 24:40] = True
    new_backdrop, new_object = original.clone(), original.clone()
    new_backdrop[0, :8] = 0.0
    new_object[0, 24:40, 24:40] = _photo(3, 16)
    assert metrics.object_ssim(new_backdrop, original, covered) == pytest.approx(1.0, abs=1e-6)
    assert metrics.object_ssim(new_object, original, covered) < 0.5 < paper_ssim(new_object, original)


def test_the_blurred_object_ssim_is_the_ssim_of_opencv_blurred_renders():
    """The oracle: OpenCV's Gaussian blur (float64, mirrored edges) at the object's-scale sigma, then SSIM."""
    a, b = _photo(4), _photo(5)
    covered = torch.ones(64, 64, dtype=torch.bool)
    sigma = metrics.OBJECT_BLUR * 64.0
    side = 2 * int(np.ceil(3.0 * sigma)) + 1  # the kernel OpenCV makes for 8-bit images (3 sigma each side)
    blur = lambda x: torch.from_numpy(
        cv2.GaussianBlur(x.double().numpy(), (side, side), sigma, borderType=cv2.BORDER_REFLECT_101)
    ).float()
    expected = paper_ssim(rec709(blur(a))[None], rec709(blur(b))[None])
    assert metrics.object_ssim(a[None], b[None], covered[None], blurred=True) == pytest.approx(expected, abs=1e-5)
    assert metrics.object_ssim(a[None], b[None], covered[None], blurred=True) > metrics.object_ssim(
        a[None], b[None], covered[None]
    )


@pytest.mark.parametrize("sigma", [0.6, 3.0, 12.5])
def test_the_blur_is_opencv_s_gaussian_blur_at_every_sigma(sigma):
    """The blur by spectra against OpenCV's direct one (float64, mirrored edges), a wide sigma included, on a
    batch of (H, W, C) images of a non-square size."""
    images = torch.stack([_photo(6, 80)[:, :72], _photo(7, 80)[:, :72]])
    side = 2 * int(np.ceil(3.0 * sigma)) + 1
    expected = [
        cv2.GaussianBlur(x.double().numpy(), (side, side), sigma, borderType=cv2.BORDER_REFLECT_101) for x in images
    ]
    got = metrics.gaussian_blur(images, sigma)
    assert got.shape == images.shape and got.dtype == images.dtype
    assert np.abs(got.numpy() - np.stack(expected)).max() < 1e-5


def test_content_metrics_are_the_paper_s_ssim_and_the_object_s():
    """The whole frame is the paper's SSIM (over the colour channels), the object's pixels object_ssim."""
    a, b = torch.stack([_photo(8), _photo(9)]), torch.stack([_photo(10), _photo(11)])
    covered = torch.zeros(2, 64, 64, dtype=torch.bool)
    covered[:, 10:50, 20:40] = True
    got = metrics.content_metrics(a, b, covered)
    assert got["ssim"] == pytest.approx(paper_ssim(a, b), abs=1e-6)
    assert got["object_ssim"] == pytest.approx(metrics.object_ssim(a, b, covered), abs=1e-6)
    assert got["object_ssim_blurred"] == pytest.approx(metrics.object_ssim(a, b, covered, blurred=True), abs=1e-6)
    assert set(metrics.content_metrics(a, b)) == {"ssim"}
