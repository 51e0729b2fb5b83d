"""Losses against brute-force float64 computations and closed forms."""

from __future__ import annotations

import math

import pytest
import torch

from gt2gs_blender.core.transfer.gt2 import match_with_prior
from gt2gs_blender.core.transfer.losses import (
    anisotropy,
    content_loss,
    cosine_distance,
    nearest_features,
    scale_regulariser,
    tv_loss,
)
from gt2gs_blender.core.transfer.texture_bank import TextureBank


def _brute_nnfm(feats: torch.Tensor, bank: torch.Tensor, groups=None, bank_groups=None):
    """Per-cell nearest bank row and cosine distance, in float64, one cell at a time."""
    b, c, h, w = feats.shape
    q = feats.double().permute(0, 2, 3, 1).reshape(-1, c)
    q = q / q.norm(dim=1, keepdim=True)
    m = bank.double() / bank.double().norm(dim=1, keepdim=True)
    idx, dist = [], []
    for i, row in enumerate(q):
        allowed = torch.arange(len(m))
        if groups is not None and int(groups.reshape(-1)[i]) >= 0:
            allowed = torch.nonzero(bank_groups == groups.reshape(-1)[i]).squeeze(1)
        sims = m[allowed] @ row
        j = int(torch.argmax(sims))
        idx.append(int(allowed[j]))
        dist.append(1.0 - float(sims[j]))
    return torch.tensor(idx).reshape(b, h, w), torch.tensor(dist, dtype=torch.float64).reshape(b, h, w)


@pytest.fixture
def data():
    g = torch.Generator().manual_seed(3)
    feats = torch.randn(2, 6, 5, 4, generator=g)
    bank = torch.randn(41, 6, generator=g)
    return feats, bank


@pytest.mark.parametrize("chunk_bytes", [64 * 2**20, 4 * 6, 4 * 7 * 13, 1])
def test_nearest_features_equal_brute_force_for_any_chunking(data, chunk_bytes):
    feats, bank = data
    queries = feats.permute(0, 2, 3, 1).reshape(-1, 6)
    idx, _ = _brute_nnfm(feats, bank)
    assert torch.equal(nearest_features(queries, bank, chunk_bytes=chunk_bytes), idx.reshape(-1))


def test_nnfm_targets_of_the_styliser_equal_brute_force_with_groups(data):
    """The no-prior matching the styliser runs (NNFM, optionally per depth group) against float64."""
    feats, bank = data
    bank_groups = torch.arange(41) % 3
    groups = torch.randint(-1, 3, (5, 4), generator=torch.Generator().manual_seed(1))
    labelled = TextureBank(bank, bank_groups, torch.zeros(41), (1.0, 0.8, 0.6), (0.0,), 1, "test")
    for grouped in (None, groups):
        match = match_with_prior(feats[0], labelled, torch.full((5, 4), math.nan), 0.0, groups=grouped)
        idx, dist = _brute_nnfm(feats[:1], bank, grouped, bank_groups)
        assert torch.equal(match.indices, idx[0])
        targets = bank[match.indices.reshape(-1)]
        distances = cosine_distance(feats[0].reshape(6, -1).T, targets).double()
        torch.testing.assert_close(distances, dist[0].reshape(-1), atol=1e-6, rtol=0)
    matched = bank_groups[match.indices]
    assert torch.equal(matched[groups >= 0], groups[groups >= 0])


def test_cosine_distance_gradient_by_finite_differences():
    g = torch.Generator().manual_seed(4)
    a = torch.randn(7, 5, dtype=torch.float64, generator=g).requires_grad_()
    b = torch.randn(7, 5, dtype=torch.float64, generator=g)
    assert torch.autograd.gradcheck(lambda x: cosine_distance(x, b), (a,))


def test_exact_matches_and_ties():
    bank = torch.eye(4)
    queries = torch.tensor([[0.0, 0.0, 5.0, 0.0], [0.5, 0.0, 0.0, 0.0], [1.0, 1.0, 0.0, 0.0]])
    assert nearest_features(queries, bank).tolist() == [2, 0, 0]  # a tie: the first row wins
    distances = cosine_distance(queries, bank[[2, 0, 0]])
    assert distances[:2].abs().max() < 1e-7
    assert float(distances[2]) == pytest.approx(1 - 1 / math.sqrt(2), abs=1e-6)


def test_tv_of_constant_image_is_zero_even_with_different_channels():
    image = torch.tensor([0.1, 0.5, 0.9]).expand(2, 7, 9, 3)
    assert float(tv_loss(image)) == 0.0
    assert float(tv_loss(image.permute(0, 3, 1, 2), channels_last=False)) == 0.0


def test_tv_of_a_ramp_is_known():
    a, b = 0.03, -0.05
    y, x = torch.meshgrid(torch.arange(6.0, dtype=torch.float64), torch.arange(8.0, dtype=torch.float64), indexing="ij")
    ramp = (a * x + b * y)[None, :, :, None].expand(1, 6, 8, 3)
    assert float(tv_loss(ramp)) == pytest.approx((a * a + b * b) / 2, rel=1e-12)
    assert float(tv_loss(ramp[0].permute(2, 0, 1), channels_last=False)) == pytest.approx((a * a + b * b) / 2)


def test_content_loss_is_feature_mse():
    f = torch.zeros(1, 2, 3, 3)
    g = torch.ones(1, 2, 3, 3) * 2.0
    assert float(content_loss(f, g)) == 4.0 and float(content_loss(g, g)) == 0.0


def test_scale_regulariser_penalises_the_largest_to_second_ratio():
    log_scales = torch.log(torch.tensor([[0.5, 2.0, 1.0], [1.0, 1.0, 1.0], [3.0, 0.1, 1.0]])).requires_grad_()
    value = scale_regulariser(log_scales)
    assert float(value.detach()) == pytest.approx(((2.0 - 1) + 0.0 + (3.0 - 1)) / 3)
    value.backward()
    assert torch.isfinite(log_scales.grad).all() and log_scales.grad[1].abs().max() < 1e-12
    assert float(scale_regulariser(log_scales.detach(), threshold=2.5)) == pytest.approx(0.5 / 3)


def test_scale_regulariser_takes_a_threshold_per_gaussian():
    """Ratios 2, 1 and 3 against thresholds 2.5, 1 and 2: only the third exceeds its own, by 1."""
    log_scales = torch.log(torch.tensor([[0.5, 2.0, 1.0], [1.0, 1.0, 1.0], [3.0, 0.1, 1.0]])).requires_grad_()
    assert torch.allclose(anisotropy(log_scales.detach()), torch.tensor([2.0, 1.0, 3.0]))
    value = scale_regulariser(log_scales, torch.tensor([2.5, 1.0, 2.0]))
    assert float(value.detach()) == pytest.approx(1.0 / 3)
    value.backward()
    assert log_scales.grad[:2].abs().max() == 0 and log_scales.grad[2].abs().max() > 0
