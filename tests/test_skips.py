"""The skips of the speed work (module ``skips`` and their wiring): each one does what it says on
inputs whose answer is known."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from gt2gs_blender.core.cameras.generate import auto_views
from gt2gs_blender.core.transfer.bank import CACHE_ENV, bank_angle_count, cache_dir
from gt2gs_blender.core.transfer.config import TransferConfig
from gt2gs_blender.core.transfer.content import clear_caches, content_and_hidden
from gt2gs_blender.core.transfer.gt2 import match_with_prior
from gt2gs_blender.core.transfer.pipeline import transfer
from gt2gs_blender.core.transfer.skips import (
    Plateau,
    angles_for,
    near_duplicates,
    redundant_views,
    texture_anisotropy,
    used_sh_degree,
)
from gt2gs_blender.core.transfer.texture_bank import TextureBank, build_texture_bank, compact_bank
from gt2gs_blender.core.transfer.views import render_views

from .test_transfer import blob_scene, stripes, tiny


# -- anisotropy -> angles ------------------------------------------------------------------------------
def sine_stripes(size: int = 128, period: float = 9.0, angle: float = 30.0) -> np.ndarray:
    y, x = np.mgrid[0:size, 0:size].astype(np.float32)
    t = math.radians(angle)
    wave = 0.5 + 0.5 * np.sin(2 * np.pi * (x * math.cos(t) + y * math.sin(t)) / period)
    return np.repeat(wave[..., None], 3, axis=2).astype(np.float32)


def test_stripes_are_anisotropic_and_white_noise_is_not() -> None:
    noise = np.random.default_rng(0).random((128, 128, 3)).astype(np.float32)
    stripes_a = texture_anisotropy(sine_stripes())
    assert stripes_a > 0.9
    assert texture_anisotropy(noise) < 0.2
    assert texture_anisotropy(np.full((64, 64, 3), 0.5, np.float32)) == 0.0  # flat: nothing to orient
    # the orientation itself does not matter, only its strength
    assert abs(texture_anisotropy(sine_stripes(angle=75.0)) - stripes_a) < 0.05


def test_angle_count_follows_anisotropy_and_divides_the_users_count() -> None:
    assert angles_for(0.95, 72) == 72
    assert angles_for(0.05, 72) == 8
    middle = angles_for(0.3, 72)
    assert 8 < middle < 72 and 72 % middle == 0
    assert angles_for(0.0, 4) == 4  # never more than asked
    counts = [angles_for(a, 360) for a in np.linspace(0, 1, 21)]
    assert counts == sorted(counts)


def test_adaptive_angles_only_when_asked() -> None:
    noise = np.random.default_rng(1).random((96, 96, 3)).astype(np.float32)
    assert bank_angle_count(noise, TransferConfig(n_angles=72)) == 72
    assert bank_angle_count(noise, TransferConfig(n_angles=72, adaptive_angles=True)) == 8
    assert bank_angle_count(sine_stripes(), TransferConfig(n_angles=72, adaptive_angles=True)) == 72


def test_angle_offset_puts_the_start_angle_on_the_grid() -> None:
    bank = build_texture_bank(
        stripes(64),
        lambda x: F.avg_pool2d(x, 4),
        extractor_id="pool",
        n_scales=1,
        n_angles=4,
        texture_height=64,
        cells=2,
        angle_offset=10.0,
    )
    assert bank.angles == (10.0, 100.0, 190.0, 280.0)
    assert set(bank.theta.tolist()) == set(bank.angles)


# -- near duplicates and PCA ----------------------------------------------------------------------------
def test_dedup_removes_exact_duplicates_and_keeps_distinct_features() -> None:
    g = torch.Generator().manual_seed(0)
    distinct = F.normalize(torch.randn(40, 64, generator=g), dim=1)  # random in 64-D: cos well below 0.99
    rows = torch.cat([distinct, distinct[:10], distinct[5:8] * 3.0])  # exact (and scaled) copies at the end
    drop = near_duplicates(rows, torch.zeros(len(rows), dtype=torch.long), 0.99, chunk=16)
    assert not drop[:40].any() and drop[40:].all()
    # a twin in another block is not a duplicate
    blocks = torch.cat([torch.zeros(40), torch.ones(10)]).long()
    assert not near_duplicates(rows[:50], blocks, 0.99).any()


def test_compacted_bank_keeps_labels_and_drops_twins_only() -> None:
    g = torch.Generator().manual_seed(1)
    base = F.normalize(torch.randn(16, 32, generator=g), dim=1)
    features = torch.cat([base, base])  # group 1 repeats group 0: no twin within a group
    features[3] = features[2]  # one twin inside group 0
    k = torch.arange(2).repeat_interleave(16)
    theta = torch.tensor([0.0, 90.0]).repeat_interleave(8).repeat(2)
    bank = TextureBank(features, k, theta, (1.0, 0.5), (0.0, 90.0), 2, "t")
    small = compact_bank(bank, dedup_threshold=0.99)
    assert len(small) == 31
    kept = torch.ones(32, dtype=torch.bool)
    kept[3] = False
    assert torch.equal(small.k, k[kept]) and torch.equal(small.theta, theta[kept])
    assert compact_bank(bank) is bank


def test_pca_matching_agrees_with_full_matching_for_well_separated_features() -> None:
    g = torch.Generator().manual_seed(2)
    n_angles, per_angle, channels, rank = 6, 8, 96, 12
    # bank features in a 12-D subspace of 96 channels, far apart; queries near bank rows, with
    # noise in every channel
    basis = torch.linalg.qr(torch.randn(channels, rank, generator=g)).Q
    features = F.normalize(torch.randn(n_angles * per_angle, rank, generator=g), dim=1) @ basis.T
    theta = (torch.arange(n_angles) * 60.0).repeat_interleave(per_angle)
    bank = TextureBank(
        features,
        torch.zeros(len(features), dtype=torch.long),
        theta,
        (1.0,),
        tuple(float(a) for a in range(0, 360, 60)),
        2,
        "t",
    )
    pick = torch.randint(len(features), (7 * 9,), generator=g)
    feats = (features[pick] + 0.02 * torch.randn(len(pick), channels, generator=g)).T.reshape(channels, 7, 9)
    prior = torch.full((7, 9), math.nan)
    full = match_with_prior(feats, bank, prior, 0.0)
    reduced = match_with_prior(feats, compact_bank(bank, pca_channels=rank), prior, 0.0)
    assert torch.equal(full.indices.reshape(-1), pick)
    assert torch.equal(reduced.indices, full.indices)
    with_prior = match_with_prior(feats, compact_bank(bank, pca_channels=rank), torch.full((7, 9), 120.0), 0.002)
    assert torch.equal(with_prior.indices, match_with_prior(feats, bank, torch.full((7, 9), 120.0), 0.002).indices)


# -- views ----------------------------------------------------------------------------------------------
def test_a_duplicated_camera_is_dropped_and_distinct_ones_are_kept() -> None:
    scene = blob_scene()
    cameras = auto_views(scene, 4, width=48, height=48)  # 90 degrees apart: each sees new sides
    cameras = [*cameras, cameras[1]]
    views = render_views(scene, cameras, torch.ones(3), "auto")
    dropped = redundant_views(cameras, views.depths, views.alphas, [0, 1, 4, 2, 3])
    assert dropped == [4]
    assert redundant_views(cameras[:4], views.depths[:4], views.alphas[:4], [0, 1, 2, 3]) == []


def test_dropping_views_in_a_transfer_reports_the_dropped_view(tmp_path) -> None:
    scene = blob_scene()
    cameras = auto_views(scene, 3, width=48, height=48)
    result = transfer(
        scene, stripes(), [*cameras, cameras[0]], tiny(cache_dir=str(tmp_path), drop_views=True, evaluate=True)
    )
    assert result.report["skips"]["dropped_views"] == [3]
    assert result.report["metrics"]["ssim"] > 0  # evaluated on every view, the dropped one too


# -- plateau --------------------------------------------------------------------------------------------
def test_plateau_stops_on_a_flat_loss_and_not_on_a_decreasing_one() -> None:
    flat, falling, off = Plateau(5, 0.01), Plateau(5, 0.01), Plateau(0, 0.01)
    flat_stops = [flat.update(1.0 + 0.001 * (-1) ** i) for i in range(20)]
    assert flat_stops.index(True) == 9  # as soon as two full windows exist
    assert not any(falling.update(math.exp(-0.05 * i)) for i in range(200))
    assert not any(off.update(1.0) for _ in range(50))
    rising = Plateau(3, 0.01)
    assert [rising.update(x) for x in (1, 1, 1, 2, 2, 2)][-1]  # getting worse is a plateau too


def test_plateau_cuts_a_transfer_short(tmp_path) -> None:
    config = tiny(cache_dir=str(tmp_path), stylise_steps=40, plateau_window=3, plateau_tol=1.0)
    report = transfer(blob_scene(), stripes(), None, config).report
    assert report["stylise"]["stylise_steps"] == 6 and report["skips"]["plateau_skipped"] == {"stylise": 34}


# -- SH bands -------------------------------------------------------------------------------------------
def test_used_sh_degree_ignores_zero_bands_and_renders_are_identical() -> None:
    scene = blob_scene().with_sh_degree(3)
    assert scene.sh_degree == 3 and used_sh_degree(scene) == 0
    rest = scene.sh_rest.clone()
    rest[5, 4, 1] = 0.3  # a degree-2 coefficient
    assert used_sh_degree(replace(scene, sh_rest=rest)) == 2
    cameras = auto_views(scene, 2, width=32, height=32)
    full = render_views(scene, cameras, torch.ones(3), "auto")
    used = render_views(scene, cameras, torch.ones(3), "auto", sh_degree=0)
    assert all(torch.equal(a, b) for a, b in zip(full.premultiplied, used.premultiplied))


# -- caches ---------------------------------------------------------------------------------------------
def test_bank_cache_hit_is_identical_and_a_changed_texture_misses(tmp_path) -> None:
    calls = {"n": 0}

    def extractor(x: torch.Tensor) -> torch.Tensor:
        calls["n"] += 1
        return F.avg_pool2d(x, 4)

    settings = {
        "extractor_id": "pool",
        "n_scales": 2,
        "n_angles": 4,
        "texture_height": 64,
        "cells": 2,
        "cache_dir": tmp_path,
    }
    first = build_texture_bank(stripes(64), extractor, **settings)
    built = calls["n"]
    again = build_texture_bank(stripes(64), extractor, **settings)
    assert calls["n"] == built  # a hit: the extractor did not run
    assert torch.equal(first.features, again.features) and torch.equal(first.theta, again.theta)
    changed = stripes(64)
    changed[0, 0] = 0.0
    build_texture_bank(changed, extractor, **settings)
    assert calls["n"] > built  # one changed pixel misses
    assert len(list(tmp_path.glob("bank-*.npz"))) == 2


def test_cache_folder_from_config_env_or_home(tmp_path, monkeypatch) -> None:
    monkeypatch.setenv(CACHE_ENV, str(tmp_path / "env"))
    assert cache_dir(TransferConfig()) == tmp_path / "env"
    assert cache_dir(TransferConfig(cache_dir=str(tmp_path / "cfg"))) == tmp_path / "cfg"
    assert cache_dir(TransferConfig(bank_cache=False)) is None
    monkeypatch.delenv(CACHE_ENV)
    assert cache_dir(TransferConfig()).parts[-3:] == (".cache", "gt2gs_blender", "banks")


def test_content_cache_reuses_renders_for_the_same_scene_and_views_only() -> None:
    clear_caches()
    scene = blob_scene()
    cameras = auto_views(scene, 2, width=32, height=32)
    config = TransferConfig()
    first = content_and_hidden(scene, cameras, torch.ones(3), config)
    assert content_and_hidden(scene.clone(), cameras, torch.ones(3), config)[0] is first[0]
    moved = scene.clone()
    moved.means[0, 0] += 0.01
    assert content_and_hidden(moved, cameras, torch.ones(3), config)[0] is not first[0]
    assert content_and_hidden(scene, cameras, torch.ones(3), TransferConfig(reuse_content=False))[0] is not first[0]
    clear_caches()


@pytest.mark.parametrize(
    "bad",
    [
        {"dedup_threshold": 1.5},
        {"match_channels": -1},
        {"plateau_window": -2},
        {"feature_scale": 0.0},
        {"min_new_coverage": 2.0},
    ],
)
def test_bad_skip_settings_are_refused(bad) -> None:
    with pytest.raises(ValueError):
        TransferConfig(**bad)
