"""Texture feature bank: labels and scales, the rotation convention, the disk cache, depth groups."""

from __future__ import annotations

import logging
import math

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from gt2gs_blender.core.errors import GT2GSError
from gt2gs_blender.core.transfer.texture_bank import (
    bank_scales,
    build_texture_bank,
    cell_groups,
    covered_cells,
    crop_side,
    depth_groups,
    feature_map_bank,
    group_depth_ratio,
    rotate_crop,
)


class OrientedEnergy(torch.nn.Module):
    """A small deterministic extractor that sees orientation AND direction but not phase:
    grey -> Sobel derivatives along 8 directions -> ReLU^2 -> 16x16 average pooling, stride 4."""

    def __init__(self) -> None:
        super().__init__()
        sobel = torch.tensor([[-1.0, 0.0, 1.0], [-2.0, 0.0, 2.0], [-1.0, 0.0, 1.0]]) / 8.0
        a = torch.arange(8) * 2 * math.pi / 8
        weight = torch.cos(a)[:, None, None] * sobel + torch.sin(a)[:, None, None] * sobel.T
        self.register_buffer("weight", weight[:, None])

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        d = F.conv2d(x.mean(1, keepdim=True), self.weight, padding=1)
        return F.avg_pool2d(F.relu(d).square(), 16, stride=4, padding=6, count_include_pad=False)


class Spy(torch.nn.Module):
    """Wraps an extractor and records the input batch shapes it sees."""

    def __init__(self, inner: torch.nn.Module) -> None:
        super().__init__()
        self.inner = inner
        self.shapes: list[tuple[int, ...]] = []

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        self.shapes.append(tuple(x.shape))
        return self.inner(x)


def stripes(size: int, phi: float, period: float = 8.0) -> np.ndarray:
    """Asymmetric-profile stripes whose profile runs along direction phi, counter-clockwise on screen
    (pixel direction (cos phi, -sin phi) with y down), about the image centre."""
    y, x = np.mgrid[0:size, 0:size].astype(np.float64) - (size - 1) / 2.0
    u = (x * math.cos(math.radians(phi)) - y * math.sin(math.radians(phi))) / period
    grey = 0.5 + 0.3 * np.sin(2 * np.pi * u) + 0.12 * np.sin(4 * np.pi * u)
    return np.repeat(grey[:, :, None], 3, axis=2).astype(np.float32)


def noise_texture(height: int = 96, width: int = 112, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).uniform(0, 1, size=(height, width, 3)).astype(np.float32)


def test_labels_scales_and_counts():
    spy = Spy(OrientedEnergy())
    bank = build_texture_bank(
        noise_texture(),
        spy,
        extractor_id="toy",
        n_scales=3,
        n_angles=8,
        texture_height=128,
        cells=2,
        batch_pixels=3 * 80 * 80,
    )
    assert len(bank) == 3 * 8 * 2 * 2 and bank.features.shape == (96, 8) and bank.features.dtype == torch.float32
    torch.testing.assert_close(bank.features.norm(dim=1), torch.ones(96))
    assert bank.scales == pytest.approx((1.0, 1 / 1.5, 0.5)) and bank.angles == tuple(range(0, 360, 45))
    assert torch.equal(bank.k, torch.arange(3).repeat_interleave(32))
    labels = {(int(k), float(t)) for k, t in zip(bank.k, bank.theta, strict=True)}
    assert labels == {(k, float(t)) for k in range(3) for t in range(0, 360, 45)}
    assert all(int((bank.k == k).sum()) == 32 for k in range(3))
    # heights 128, 85, 64 -> crops 96/1.41 -> 80, then 48 and 32 (multiples of 16) are below 64 px:
    # those scales are tiled and cut at 64; batched <= 3 at 80^2
    sides = [s[-1] for s in spy.shapes]
    expected = [crop_side(128, 149), 64]
    assert sorted(set(sides), reverse=True) == expected == [80, 64]
    assert max(s[0] for s in spy.shapes if s[-1] == 80) == 3 and sum(s[0] for s in spy.shapes) == 24


def test_feature_map_bank_is_every_cell_of_the_texture_as_it_lies():
    """NNFM's bank: the whole map at texture_height, unrotated (its cells match the labelled bank's
    photo angle), unlabelled."""
    extractor = OrientedEnergy()
    labelled = build_texture_bank(
        stripes(128, 0.0), extractor, extractor_id="toy", n_scales=1, n_angles=36, texture_height=128, cells=4
    )
    bank = feature_map_bank(stripes(256, 30.0), extractor, extractor_id="toy", texture_height=128)
    assert len(bank) == 32 * 32 and bank.features.shape == (1024, 8)  # 128 px at stride 4
    torch.testing.assert_close(bank.features.norm(dim=1), torch.ones(1024))
    assert bank.scales == (1.0,) and bank.angles == (0.0,) and not bank.k.any() and not bank.theta.any()
    inner = bank.features.reshape(32, 32, 8)[4:-4, 4:-4].reshape(-1, 8)  # away from the padded border
    theta = labelled.theta[(inner @ labelled.features.T).argmax(dim=1)]
    error = (theta - 30.0 + 180.0) % 360.0 - 180.0
    assert error.abs().max() <= 5.0 + 1e-6
    with pytest.raises(ValueError, match="texture_height"):
        feature_map_bank(stripes(64, 0.0), extractor, extractor_id="toy", texture_height=0)


def test_bank_scales_follow_the_depth_ratio():
    assert bank_scales(4) == pytest.approx((1.0, 0.75, 0.6, 0.5))
    assert bank_scales(1) == (1.0,)
    with pytest.raises(ValueError):
        bank_scales(0)


def test_best_matching_label_of_rotated_stripes_is_their_angle():
    extractor = OrientedEnergy()
    bank = build_texture_bank(
        stripes(128, 0.0), extractor, extractor_id="toy", n_scales=1, n_angles=36, texture_height=128, cells=4
    )
    for phi in (30.0, 47.0, 123.0, 200.0, 293.0):
        feats = extractor(torch.from_numpy(stripes(96, phi)).permute(2, 0, 1)[None])[0, :, 3:-3, 3:-3]
        queries = F.normalize(feats.permute(1, 2, 0).reshape(-1, 8), dim=1)
        theta = bank.theta[(queries @ bank.features.T).argmax(dim=1)]
        error = (theta - phi + 180.0) % 360.0 - 180.0
        assert error.abs().max() <= 5.0 + 1e-6, (phi, theta.tolist())


def test_rotating_the_texture_by_90_degrees_shifts_the_labels_by_90():
    texture = noise_texture(128, 128, seed=4)
    extractor = OrientedEnergy()
    kwargs = {"extractor_id": "toy", "n_scales": 1, "n_angles": 12, "texture_height": 128, "cells": 4}
    bank = build_texture_bank(texture, extractor, **kwargs)
    turned = build_texture_bank(np.ascontiguousarray(np.rot90(texture)), extractor, **kwargs)  # 90 deg CCW
    per_angle = 16
    for a in range(12):
        shifted = (a + 3) % 12
        ours = turned.features[a * per_angle : (a + 1) * per_angle]
        theirs = bank.features[shifted * per_angle : (shifted + 1) * per_angle]
        assert float((ours * theirs).sum(dim=1).min()) > 0.995, a


def test_rotate_crop_is_exact_for_quarter_turns_and_never_shows_a_border():
    texture = noise_texture(64, 64, seed=2)
    side = crop_side(64, 64)
    centre = texture[(64 - side) // 2 : (64 + side) // 2, (64 - side) // 2 : (64 + side) // 2]
    np.testing.assert_allclose(rotate_crop(texture, 0.0, side), centre, atol=1e-6)
    np.testing.assert_allclose(rotate_crop(texture, 90.0, side), np.rot90(centre), atol=1e-5)
    ones = np.ones((64, 80, 3), np.float32)
    for angle in (13.0, 45.0, 171.0):
        assert np.abs(rotate_crop(ones, angle, crop_side(64, 80)) - 1.0).max() < 1e-5


def test_capped_crops_give_the_same_centre_features_when_they_cover_the_receptive_field():
    texture = noise_texture(128, 128, seed=6)
    spy = Spy(OrientedEnergy())
    kwargs = {"extractor_id": "toy", "n_scales": 1, "n_angles": 5, "texture_height": 128, "cells": 4}
    full = build_texture_bank(texture, OrientedEnergy(), **kwargs)
    capped = build_texture_bank(texture, spy, max_crop=50, **kwargs)  # 16 px of cells + 2 x 9 px of field
    assert {s[-1] for s in spy.shapes} == {48}
    torch.testing.assert_close(capped.features, full.features, atol=1e-6, rtol=0)


def test_cache_hit_is_identical_and_keyed_by_content_and_settings(tmp_path):
    texture = noise_texture(64, 64, seed=1)
    spy = Spy(OrientedEnergy())
    kwargs = {
        "extractor_id": "toy-v1",
        "n_scales": 2,
        "n_angles": 6,
        "texture_height": 96,
        "cells": 2,
        "cache_dir": tmp_path,
    }
    first = build_texture_bank(texture, spy, **kwargs)
    calls = len(spy.shapes)
    assert calls > 0 and len(list(tmp_path.glob("bank-*.npz"))) == 1
    again = build_texture_bank(texture.copy(), spy, **kwargs)
    assert len(spy.shapes) == calls
    for name in ("features", "k", "theta"):
        assert torch.equal(getattr(first, name), getattr(again, name))
    assert (again.scales, again.angles, again.cells, again.extractor_id) == (first.scales, first.angles, 2, "toy-v1")
    changed = texture.copy()
    changed[10, 20, 1] += 0.01
    build_texture_bank(changed, spy, **kwargs)
    assert len(spy.shapes) > calls
    for change in ({"extractor_id": "toy-v2"}, {"n_angles": 7}, {"depth_ratio_range": (1.0, 3.0)}):
        before = len(spy.shapes)
        build_texture_bank(texture, spy, **{**kwargs, **change})
        assert len(spy.shapes) > before, change
    assert len(list(tmp_path.glob("bank-*.npz"))) == 5


def test_corrupt_cache_is_rebuilt_with_a_warning(tmp_path, caplog):
    texture = noise_texture(64, 64, seed=1)
    kwargs = {
        "extractor_id": "toy",
        "n_scales": 1,
        "n_angles": 4,
        "texture_height": 96,
        "cells": 2,
        "cache_dir": tmp_path,
    }
    good = build_texture_bank(texture, OrientedEnergy(), **kwargs)
    (cache,) = tmp_path.glob("bank-*.npz")
    cache.write_bytes(cache.read_bytes()[:100])
    with caplog.at_level(logging.WARNING, logger="gt2gs_blender"):
        rebuilt = build_texture_bank(texture, OrientedEnergy(), **kwargs)
    assert "ignoring the texture bank cache" in caplog.text
    assert torch.equal(rebuilt.features, good.features)
    assert torch.equal(build_texture_bank(texture, lambda x: 1 / 0, **kwargs).features, good.features)


def test_progress_is_reported_and_too_many_cells_are_a_clear_error():
    seen: list[float] = []
    build_texture_bank(
        noise_texture(),
        OrientedEnergy(),
        extractor_id="toy",
        n_scales=2,
        n_angles=5,
        texture_height=96,
        cells=2,
        batch_pixels=1,
        progress=seen.append,
    )
    assert seen == sorted(seen) and seen[-1] == pytest.approx(1.0) and len(seen) == 10
    small = build_texture_bank(
        noise_texture(), OrientedEnergy(), extractor_id="toy", n_scales=1, n_angles=2, texture_height=40, cells=8
    )
    assert len(small) == 2 * 8 * 8  # a 40 px texture is tiled up to a 64 px crop, not refused
    with pytest.raises(GT2GSError, match="too small for the feature bank"):
        build_texture_bank(
            noise_texture(), OrientedEnergy(), extractor_id="toy", n_scales=1, n_angles=2, texture_height=40, cells=80
        )


def test_depth_groups_bin_the_surface_depth_nearest_first():
    z = torch.tensor([2.0, 2.4, 3.2, 3.9, 4.2, 4.9, 5.1, 5.8, 6.0]).repeat(3, 1)  # bin edges 3, 4, 5
    alpha = torch.full_like(z, 0.8)
    alpha[2, :4] = 0.2  # poorly covered: no group
    groups = depth_groups(z * alpha, alpha, 4)  # the rasterizer's depth is sum(T alpha z)
    assert groups[0].tolist() == [0, 0, 1, 1, 2, 2, 3, 3, 3]
    assert groups[2].tolist() == [-1, -1, -1, -1, 2, 2, 3, 3, 3]
    fixed = depth_groups(z * alpha, alpha, 2, depth_range=(0.0, 13.0))
    assert fixed[0].tolist() == [0] * 9
    assert depth_groups(z, torch.zeros_like(z), 3).eq(-1).all()
    assert depth_groups(torch.ones(2, 2), torch.ones(2, 2), 3).eq(0).all()


def test_group_depth_ratio_is_the_far_over_the_near_bin_centre():
    z = torch.linspace(2.0, 4.0, 101).repeat(2, 1)  # bins of 0.5: centres 2.25 ... 3.75
    alpha = torch.full_like(z, 0.9)
    alpha[1, 60:] = 0.1  # poorly covered pixels don't count
    assert group_depth_ratio(z * alpha, alpha, 4) == pytest.approx(3.75 / 2.25)
    assert group_depth_ratio(z[:1] * alpha[:1], alpha[:1], 2) == pytest.approx(3.5 / 2.5)
    assert group_depth_ratio(z * alpha, alpha, 1) == 1.0
    assert group_depth_ratio(z, torch.zeros_like(z), 4) == 1.0


@pytest.mark.parametrize("near, far", [(2.0, 3.0), (10.0, 11.0), (1.0, 1.8)])
def test_measured_bank_scales_give_every_depth_group_the_same_world_scale(near, far):
    """Paper §3.2: a group's texture is shown Z_1/Z_k as large, so that a surface gets the same texture
    size in the world (image size x depth) whichever group a view puts it in; the authors' fixed
    ratio 2 would shrink a shallow scene's far groups too much (a surface 157 degrees round an orbit
    flips from near to far and would get two sizes)."""
    z = torch.linspace(near, far, 4001)
    alpha = torch.ones_like(z)
    groups = depth_groups(z, alpha, 4)
    mean_depth = torch.stack([z[groups == k].mean() for k in range(4)])
    world = torch.tensor(bank_scales(4, (1.0, group_depth_ratio(z, alpha, 4)))) * mean_depth
    assert torch.allclose(world, world[0], rtol=1e-3)
    fixed = torch.tensor(bank_scales(4, (1.0, 2.0))) * mean_depth
    assert (fixed[-1] / fixed[0]).item() < 0.8


def test_cell_groups_take_the_most_frequent_group_of_each_cell():
    groups = torch.tensor(
        [
            [0, 0, 1, 1, 2, 2],
            [0, 1, 1, 1, 2, -1],
            [3, 3, -1, -1, 2, 2],
            [3, 0, -1, 1, -1, -1],
        ]
    )
    assert cell_groups(groups, (2, 3)).tolist() == [[0, 1, 2], [3, -1, -1]]
    batch = torch.stack([groups, groups.flip(-1)])
    out = cell_groups(batch, (2, 3))
    assert out.shape == (2, 2, 3) and out[0].tolist() == [[0, 1, 2], [3, -1, -1]]
    assert out[1].tolist() == [[2, 1, 0], [-1, -1, 3]]
    assert cell_groups(torch.arange(6).reshape(2, 3), (2, 3)).tolist() == [[0, 1, 2], [3, 4, 5]]


def test_covered_cells_need_a_majority_of_covered_pixels():
    alpha = torch.tensor(
        [
            [1.0, 1.0, 0.6, 0.0],
            [1.0, 0.0, 0.4, 0.0],
            [0.5, 0.5, 0.0, 0.0],
            [0.49, 0.9, 0.0, 1.0],
        ]
    )
    # cells of 2x2 pixels: 3/4, 1/4, 3/4 and 1/4 covered at alpha >= 0.5
    assert covered_cells(alpha, (2, 2)).tolist() == [[True, False], [True, False]]
    # exactly half covered is not a majority
    assert covered_cells(torch.tensor([[1.0, 0.0]]), (1, 1)).tolist() == [[False]]
    batch = covered_cells(torch.stack([alpha, alpha.flip(-1)]), (2, 2))
    assert batch.shape == (2, 2, 2) and batch[1].tolist() == [[False, True], [False, True]]
    assert covered_cells(alpha, (4, 4)).tolist() == (alpha >= 0.5).tolist()
    # fraction 1: only wholly covered cells (none of the 2x2 cells here; a 1x2 one)
    assert not covered_cells(alpha, (2, 2), fraction=1.0).any()
    assert covered_cells(torch.tensor([[1.0, 0.7], [0.2, 0.9]]), (2, 1), fraction=1.0).tolist() == [[True], [False]]
    assert covered_cells(alpha, (2, 2), fraction=0.0).tolist() == [[True, True], [True, True]]
    finer = covered_cells(torch.ones(1, 2), (1, 4), fraction=1.0)  # a grid finer than the image: empty cells
    assert finer.sum() == 2 and finer.tolist() == covered_cells(torch.ones(1, 2), (1, 4)).tolist()
