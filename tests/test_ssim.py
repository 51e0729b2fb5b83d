"""SSIM against the reference libraries' values (pytorch_msssim, skimage) and its gradient."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
import torch

from gt2gs_blender.core.train.ssim import gaussian_window, ssim, ssim_map

PAIRS = {
    "image000_vs_image001": lambda a, b: b,
    "image000_vs_roll2px": lambda a, b: np.roll(a, 2, axis=1),
    "image000_vs_times0.8": lambda a, b: a * 0.8,
    "image000_vs_quantized15": lambda a, b: np.round(a * 15) / 15,
    "image000_vs_itself": lambda a, b: a,
}


def fern_rgb(shared, index: int) -> np.ndarray:
    path = shared / "data" / "scenes" / "fern_llff" / "images_8" / f"image{index:03d}.png"
    return cv2.cvtColor(cv2.imread(str(path)), cv2.COLOR_BGR2RGB).astype(np.float32) / 255.0


@pytest.mark.parametrize("pair", sorted(PAIRS))
@pytest.mark.parametrize("library", ["ssim_pytorch_msssim", "ssim_skimage"])
def test_matches_reference_values(shared, pair, library):
    refs = json.loads((shared / "data" / "reference" / "metric_refs.json").read_text())["values"]
    a, b = fern_rgb(shared, 0), fern_rgb(shared, 1)
    other = PAIRS[pair](a, b).astype(np.float32)
    value = float(ssim(torch.from_numpy(a), torch.from_numpy(other)))
    assert value == pytest.approx(refs[pair][library], abs=1e-4)


def test_window_is_normalised_and_symmetric():
    w = gaussian_window(dtype=torch.float64)
    assert w.shape == (11,) and float(w.sum()) == pytest.approx(1.0)
    assert torch.equal(w, w.flip(0)) and int(w.argmax()) == 5


def test_batch_gives_per_image_scores_and_identity_is_one():
    x = torch.rand(3, 20, 24, 3, dtype=torch.float64)
    y = torch.rand(3, 20, 24, 3, dtype=torch.float64)
    scores = ssim(x, y)
    assert scores.shape == (3,)
    assert torch.allclose(scores, torch.stack([ssim(x[i], y[i]) for i in range(3)]))
    assert torch.allclose(ssim(x, x), torch.ones(3, dtype=torch.float64))
    assert torch.allclose(scores, ssim(y, x))
    assert ssim_map(x, y).shape == (3, 3, 10, 14)


def test_gradient_matches_finite_differences():
    x = torch.rand(1, 12, 13, 2, dtype=torch.float64, requires_grad=True)
    y = torch.rand(1, 12, 13, 2, dtype=torch.float64)
    assert torch.autograd.gradcheck(lambda t: ssim(t, y), (x,))


def test_rejects_bad_shapes():
    with pytest.raises(ValueError, match="one shape"):
        ssim(torch.rand(16, 16, 3), torch.rand(16, 17, 3))
    with pytest.raises(ValueError, match="at least 11x11"):
        ssim(torch.rand(10, 16, 3), torch.rand(10, 16, 3))
