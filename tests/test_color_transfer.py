"""Colour transfer: target statistics reached, degenerate inputs safe, and the SH-space map exact."""

from __future__ import annotations

import logging

import numpy as np
import pytest
import torch

from gt2gs_blender.core.cameras.poses import orbit_views
from gt2gs_blender.core.render import render
from gt2gs_blender.core.scene.gaussians import SH_C0, GaussianScene
from gt2gs_blender.core.transfer.color_transfer import apply_to_images, apply_to_scene, fit_color_transform


def _coloured_pixels(n: int, mix: np.ndarray, mean: np.ndarray, seed: int) -> np.ndarray:
    """n correlated RGB pixels: mean + mix @ uniform noise."""
    z = np.random.default_rng(seed).uniform(-0.5, 0.5, size=(n, 3))
    return mean + z @ mix.T


def _moments(x: np.ndarray, w: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    w = np.ones(len(x)) if w is None else w
    mu = (w[:, None] * x).sum(0) / w.sum()
    d = x - mu
    return mu, (w[:, None] * d).T @ d / w.sum()


CONTENT_MIX = np.array([[0.30, 0.05, 0.00], [0.10, 0.25, 0.02], [0.00, 0.08, 0.20]])
TEXTURE_MIX = np.array([[0.10, 0.20, 0.05], [0.00, 0.15, 0.00], [0.12, 0.00, 0.30]])


def test_output_has_the_texture_mean_and_covariance():
    content = _coloured_pixels(4 * 30 * 40, CONTENT_MIX, np.array([0.4, 0.5, 0.3]), 1).reshape(4, 30, 40, 3)
    texture = _coloured_pixels(50 * 60, TEXTURE_MIX, np.array([0.6, 0.3, 0.5]), 2).reshape(50, 60, 3)
    A, b = fit_color_transform(torch.from_numpy(content), texture)
    out = apply_to_images(torch.from_numpy(content), A, b, clamp=False).numpy().reshape(-1, 3)
    mu_out, cov_out = _moments(out)
    mu_tex, cov_tex = _moments(texture.reshape(-1, 3))
    np.testing.assert_allclose(mu_out, mu_tex, atol=1e-4)
    np.testing.assert_allclose(cov_out, cov_tex, atol=1e-4)
    assert A.dtype == torch.float64 and A.shape == (3, 3) and b.shape == (3,)


def test_weights_restrict_the_statistics_to_covered_pixels():
    covered = _coloured_pixels(900, CONTENT_MIX, np.array([0.4, 0.5, 0.3]), 3)
    images = np.concatenate([covered, np.zeros((300, 3))]).reshape(4, 30, 10, 3)  # black background
    alpha = np.concatenate([np.ones(900), np.zeros(300)]).reshape(4, 30, 10)
    texture = _coloured_pixels(2000, TEXTURE_MIX, np.array([0.6, 0.3, 0.5]), 4).reshape(40, 50, 3)
    A, b = fit_color_transform(list(images), texture, weights=list(alpha))
    mu_out, cov_out = _moments(covered @ A.numpy().T + b.numpy())
    mu_tex, cov_tex = _moments(texture.reshape(-1, 3))
    np.testing.assert_allclose(mu_out, mu_tex, atol=1e-4)
    np.testing.assert_allclose(cov_out, cov_tex, atol=1e-4)


@pytest.mark.parametrize("kind", ["grey", "constant"])
def test_degenerate_content_never_gives_nan(kind):
    rng = np.random.default_rng(5)
    level = rng.uniform(0.2, 0.8, size=(2, 16, 16, 1)) if kind == "grey" else np.full((2, 16, 16, 1), 0.4)
    content = torch.from_numpy(np.repeat(level, 3, axis=-1))
    texture = _coloured_pixels(1000, TEXTURE_MIX, np.array([0.6, 0.3, 0.5]), 6).reshape(20, 50, 3)
    A, b = fit_color_transform(content, texture)
    out = apply_to_images(content, A, b, clamp=False)
    assert torch.isfinite(A).all() and torch.isfinite(b).all() and torch.isfinite(out).all()
    mu_tex = texture.reshape(-1, 3).mean(0)
    np.testing.assert_allclose(out.reshape(-1, 3).mean(0).numpy(), mu_tex, atol=1e-6)
    if kind == "constant":
        np.testing.assert_allclose(out.reshape(-1, 3).numpy(), np.broadcast_to(mu_tex, (512, 3)), atol=1e-6)


def test_constant_texture_maps_everything_to_its_colour():
    content = torch.rand(2, 8, 8, 3, dtype=torch.float64)
    A, b = fit_color_transform(content, np.full((10, 10, 3), [0.2, 0.7, 0.1]))
    assert torch.allclose(A, torch.zeros(3, 3, dtype=torch.float64), atol=1e-6)
    out = apply_to_images(content, A, b)
    assert torch.allclose(out, torch.tensor([0.2, 0.7, 0.1], dtype=torch.float64).expand_as(out), atol=1e-6)


def test_image_clamping_respects_premultiplied_alpha():
    images = torch.tensor([[[0.9, 0.9, 0.9], [0.05, 0.05, 0.05]]])
    alpha = torch.tensor([[1.0, 0.1]])
    A, b = 1.5 * torch.eye(3, dtype=torch.float64), torch.full((3,), -0.2, dtype=torch.float64)
    out = apply_to_images(images, A, b, alpha=alpha)
    assert torch.allclose(out[0, 0], torch.ones(3)) and torch.allclose(out[0, 1], torch.full((3,), 0.055))
    assert apply_to_images(images, A, b).max() <= 1.0


def _sh3_scene(n: int = 120, seed: int = 0) -> GaussianScene:
    """SH degree 3 Gaussians around the origin whose colours stay well inside (0, 1) from any side."""
    g = torch.Generator().manual_seed(seed)

    def uniform(*shape: int) -> torch.Tensor:
        return torch.rand(*shape, generator=g, dtype=torch.float64)

    scene = GaussianScene.from_activated(
        means=(uniform(n, 3) - 0.5) * 1.2,
        scales=0.08 * (0.5 + uniform(n, 3)),
        opacities=0.3 + 0.6 * uniform(n),
        colors=0.3 + 0.4 * uniform(n, 3),
        quats=torch.randn(n, 4, generator=g, dtype=torch.float64),
        sh_degree=3,
    )
    scene.sh_rest = 0.03 * torch.randn(n, 15, 3, generator=g, dtype=torch.float64)
    return scene


def test_sh_space_transform_renders_like_the_image_space_transform():
    scene = _sh3_scene()
    cameras = orbit_views((0, 0, 0), 3.0, 3, width=40, height=30, elevation_deg=25.0)
    A = torch.tensor([[0.7, 0.1, 0.05], [-0.05, 0.8, 0.1], [0.1, -0.1, 0.6]], dtype=torch.float64)
    b = torch.tensor([0.15, 0.05, 0.2], dtype=torch.float64)
    before = render(scene, cameras, backend="torch")
    after = render(apply_to_scene(scene, A, b), cameras, backend="torch")
    expected = apply_to_images(before.colors, A, b, alpha=before.alphas, clamp=False)
    assert float(before.alphas.max()) > 0.5
    torch.testing.assert_close(after.colors, expected, atol=1e-10, rtol=0)
    torch.testing.assert_close(after.alphas, before.alphas, atol=0, rtol=0)


def test_fitted_transform_on_a_scene_matches_its_content_images():
    scene = _sh3_scene(seed=1)
    cameras = orbit_views((0, 0, 0), 3.0, 2, width=32, height=24)
    before = render(scene, cameras, backend="torch")
    texture = _coloured_pixels(900, TEXTURE_MIX * 0.3, np.array([0.5, 0.45, 0.5]), 7).reshape(30, 30, 3)
    A, b = fit_color_transform(before.colors, texture, weights=before.alphas)
    after = render(apply_to_scene(scene, A, b, clamp=False), cameras, backend="torch")
    expected = apply_to_images(before.colors, A, b, alpha=before.alphas, clamp=False)
    torch.testing.assert_close(after.colors, expected, atol=1e-10, rtol=0)


def test_scene_clamping_is_reported_and_keeps_dc_colours_in_range(caplog):
    scene = _sh3_scene(n=10)
    A, b = 3.0 * torch.eye(3, dtype=torch.float64), torch.zeros(3, dtype=torch.float64)
    with caplog.at_level(logging.INFO, logger="gt2gs_blender"):
        out = apply_to_scene(scene, A, b)
    colours = 0.5 + SH_C0 * out.sh_dc
    assert colours.min() >= 0.0 and colours.max() <= 1.0 + 1e-12
    assert "clamped the colour of" in caplog.text
    assert out.sh_dc.dtype == scene.sh_dc.dtype and out.means is scene.means
