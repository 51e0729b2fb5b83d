"""AFCM: block DCT against OpenCV, frequency map, depth level and the weight formula."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import torch

from gt2gs_blender.core.transfer.afcm import (
    AFCMWeights,
    afcm_weight,
    block_dct,
    depth_level,
    high_frequency_energy,
    normalise_frequency,
)


def opencv_block_dct(gray: np.ndarray, block: int = 8) -> np.ndarray:
    """The oracle: cv2.dct on each block in turn."""
    h, w = gray.shape[0] // block, gray.shape[1] // block
    out = np.empty((h, w, block, block))
    for i in range(h):
        for j in range(w):
            out[i, j] = cv2.dct(np.ascontiguousarray(gray[i * block : (i + 1) * block, j * block : (j + 1) * block]))
    return out


def test_block_dct_equals_opencv():
    gray = np.random.default_rng(0).uniform(0, 1, size=(24, 40))
    ours = block_dct(torch.from_numpy(gray)).numpy()
    assert np.allclose(ours, opencv_block_dct(gray), atol=1e-12)
    with pytest.raises(ValueError, match="8x8 blocks"):
        block_dct(torch.zeros(10, 16))


def test_high_frequency_energy_matches_opencv_and_finds_detail():
    rng = np.random.default_rng(1)
    image = np.full((32, 32, 3), 0.5)
    image[:, 16:] += rng.uniform(-0.4, 0.4, size=(32, 16, 1))  # fine noise on the right half only
    energy = high_frequency_energy(torch.from_numpy(image).float(), (4, 4))
    gray = (image[..., 0] * 0.299 + image[..., 1] * 0.587 + image[..., 2] * 0.114).astype(np.float32)
    expected = np.abs(opencv_block_dct(gray.astype(np.float64))[..., 4:8, 4:8]).sum(axis=(-1, -2))
    assert np.allclose(energy.numpy(), expected, rtol=1e-4, atol=1e-5)
    assert float(energy[:, :2].max()) < 1e-5 < float(energy[:, 2:].min())


def test_energy_grid_follows_the_feature_grid_at_any_image_size():
    image = torch.rand(50, 70, 3)
    assert high_frequency_energy(image, (6, 9)).shape == (6, 9)
    assert high_frequency_energy(image, (10, 14)).shape == (10, 14)


def test_frequency_normalised_over_all_views_by_a_robust_maximum():
    a, b = torch.tensor([[0.0, 1.0], [2.0, 100.0]]), torch.tensor([[4.0, 4.0], [4.0, 4.0]])
    masks = [torch.tensor([[True, True], [True, False]]), torch.ones(2, 2, dtype=torch.bool)]
    na, nb = normalise_frequency([a, b], masks)
    assert float(na.max()) == 1.0 and float(nb.max()) == pytest.approx(1.0)  # 100 is uncovered: ignored
    assert float(na[0, 1]) == pytest.approx(1.0 / 4.0, rel=0.02)
    zero = normalise_frequency([torch.zeros(2, 2)], [torch.ones(2, 2, dtype=torch.bool)])
    assert float(zero[0].abs().max()) == 0.0  # a flat scene: no NaN


def test_depth_level_and_weight_formula():
    groups = torch.tensor([[0, 1], [3, -1]])
    level = depth_level(groups, 4, torch.zeros(2, 2))
    assert torch.allclose(level, torch.tensor([[0.0, 1.0 / 3.0], [1.0, 0.0]]))
    assert depth_level(None, 4, torch.zeros(2, 2)).abs().max() == 0
    w = afcm_weight(level, torch.full((2, 2), 0.5), torch.zeros(2, 2))
    expected = 0.8 * (1 - level) + 0.8 * 0.5 + 0.25
    assert torch.allclose(w, expected)
    custom = afcm_weight(torch.zeros(1), torch.zeros(1), torch.ones(1), AFCMWeights(1.0, 2.0, 3.0))
    assert float(custom) == 3.0
