"""LPIPS-Alex port against the real ``lpips`` package's values on fixed fern image pairs."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from gt2gs_blender.core.errors import GT2GSError
from gt2gs_blender.core.features.lpips import load_lpips
from gt2gs_blender.core.features.weights import ENV_VAR

from .conftest import SHARED
from .test_ssim import PAIRS, fern_rgb  # the recipes of metric_refs.json


def nchw(images: np.ndarray) -> torch.Tensor:
    return torch.from_numpy(np.ascontiguousarray(images)).permute(0, 3, 1, 2)


@pytest.fixture(scope="module")
def lpips():
    """LPIPS-Alex from the shared weights, loaded once for the module."""
    if not (SHARED / "weights").is_dir():
        pytest.skip(f"shared weights not found at {SHARED / 'weights'}")
    return load_lpips(SHARED / "weights")


def test_matches_reference_values(shared, lpips):
    refs = json.loads((shared / "data" / "reference" / "metric_refs.json").read_text())["values"]
    a, b = fern_rgb(shared, 0), fern_rgb(shared, 1)
    names = sorted(PAIRS)
    others = np.stack([PAIRS[name](a, b) for name in names]).astype(np.float32)
    with torch.no_grad():
        values = lpips(nchw(np.broadcast_to(a, others.shape)), nchw(others))
    for name, value in zip(names, values.tolist()):
        assert value == pytest.approx(refs[name]["lpips_alex"], abs=1e-6), name


def test_symmetric_and_differentiable(lpips):
    x = torch.rand(2, 3, 64, 64, requires_grad=True)
    y = torch.rand(2, 3, 64, 64)
    d = lpips(x, y)
    torch.testing.assert_close(d, lpips(y, x.detach()))
    d.sum().backward()
    assert x.grad.abs().sum() > 0 and not any(p.requires_grad for p in lpips.parameters())


def test_missing_weights_are_named(monkeypatch, tmp_path):
    monkeypatch.setenv("TORCH_HOME", str(tmp_path))
    monkeypatch.delenv(ENV_VAR, raising=False)
    with pytest.raises(GT2GSError, match=r"alexnet_features.pth"):
        load_lpips(tmp_path)
