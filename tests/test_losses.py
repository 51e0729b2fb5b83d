"""Losses against brute-force float64 computations and closed forms."""
from __future__ import annotations

import math

import pytest
import torch

from gt2gs_blender.core.losses import (
    content_loss,
    nearest_features,
    nnfm_loss,
    scale_regulariser,
    tv_loss,
)


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
def test_nnfm_equals_brute_force_for_any_chunking(data, chunk_bytes):
    feats, bank = data
    result = nnfm_loss(feats, bank, chunk_bytes=chunk_bytes)
    idx, dist = _brute_nnfm(feats, bank)
    assert torch.equal(result.indices, idx)
    torch.testing.assert_close(result.distances.double(), dist, atol=1e-6, rtol=0)
    assert float(result.loss) == pytest.approx(float(dist.mean()), abs=1e-6)


def test_nnfm_gradient_flows_to_features_against_fixed_targets(data):
    feats, bank = data
    feats64 = feats.double().requires_grad_()
    nnfm_loss(feats64, bank.double()).loss.backward()
    idx, _ = _brute_nnfm(feats, bank)
    ref = feats.double().requires_grad_()
    q = ref.permute(0, 2, 3, 1).reshape(-1, 6)
    t = bank.double()[idx.reshape(-1)]
    (1 - (q * t).sum(1) / (q.norm(dim=1) * t.norm(dim=1))).mean().backward()
    torch.testing.assert_close(feats64.grad, ref.grad, atol=1e-12, rtol=0)


def test_nnfm_mask_averages_only_counted_cells(data):
    feats, bank = data
    mask = torch.zeros(5, 4, dtype=torch.bool)
    mask[1:3, 2:] = True
    result = nnfm_loss(feats, bank, mask=mask)
    _, dist = _brute_nnfm(feats, bank)
    assert float(result.loss) == pytest.approx(float(dist[:, 1:3, 2:].mean()), abs=1e-6)
    empty = nnfm_loss(feats.requires_grad_(), bank, mask=torch.zeros(5, 4, dtype=torch.bool))
    assert float(empty.loss.detach()) == 0.0 and empty.loss.requires_grad


def test_nnfm_groups_restrict_matching_to_the_cells_group(data):
    feats, bank = data
    bank_groups = torch.arange(41) % 3
    groups = torch.randint(-1, 3, (2, 5, 4), generator=torch.Generator().manual_seed(1))
    result = nnfm_loss(feats, bank, groups=groups, bank_groups=bank_groups, chunk_bytes=4 * 6 * 3)
    idx, dist = _brute_nnfm(feats, bank, groups, bank_groups)
    assert torch.equal(result.indices, idx)
    torch.testing.assert_close(result.distances.double(), dist, atol=1e-6, rtol=0)
    matched = bank_groups[result.indices]
    assert torch.equal(matched[groups >= 0], groups[groups >= 0])
    with pytest.raises(ValueError, match="no bank features in group 5"):
        nnfm_loss(feats, bank, groups=torch.full((5, 4), 5), bank_groups=bank_groups)
    with pytest.raises(ValueError, match="bank_groups"):
        nnfm_loss(feats, bank, groups=groups)


def test_unbatched_features_and_exact_matches():
    bank = torch.eye(4)
    feats = torch.zeros(4, 1, 3)
    feats[2, 0, 0] = 5.0   # exactly bank row 2
    feats[0, 0, 1] = 0.5   # exactly bank row 0
    feats[:2, 0, 2] = 1.0  # tie between rows 0 and 1: the first wins
    result = nnfm_loss(feats, bank)
    assert result.indices.tolist() == [[2, 0, 0]]
    assert result.distances[0, :2].abs().max() < 1e-7
    assert float(result.distances[0, 2]) == pytest.approx(1 - 1 / math.sqrt(2), abs=1e-6)
    assert nearest_features(torch.tensor([[0.0, 0.0, 0.0, 1.0]]), bank).tolist() == [3]


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
