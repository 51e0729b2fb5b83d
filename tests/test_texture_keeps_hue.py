"""*Texture Loss Keeps Hue*: the feature losses may only lighten or darken, so they cannot paint hues of their own."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from gt2gs_blender.core.transfer.layout import with_colours
from gt2gs_blender.core.transfer.losses import light_only

from .test_layout import front_camera, wall, wall_config


def test_light_only_keeps_the_values_and_spreads_each_pixel_s_gradient_evenly():
    """Analytic: for L = sum(w * light_only(x)) the value is x's and dL/dx is w's mean over the channels, the same on
    all three (a grey step), where L's own gradient would be w."""
    generator = torch.Generator().manual_seed(0)
    x = torch.rand(5, 7, 3, generator=generator, requires_grad=True)
    w = torch.randn(5, 7, 3, generator=generator)
    seen = light_only(x)
    assert torch.equal(seen, x)
    (w * seen).sum().backward()
    assert torch.allclose(x.grad, w.mean(-1, keepdim=True).expand(-1, -1, 3), atol=1e-7)


def coloured_wall():
    """The test wall in mid-range colours that vary across it (no channel near 0 or 1, where a render clamps)."""
    base = wall(n=40)
    x, y = base.means[:, 0], base.means[:, 1]
    rgb = torch.stack([0.5 + 0.15 * torch.sin(3 * x), 0.45 + 0.15 * torch.cos(2 * y), 0.5 + 0.1 * x * y], -1)
    return with_colours(base, rgb)


@pytest.mark.parametrize("keeps_hue", [True, False])
def test_a_texture_loss_that_keeps_hue_moves_each_splat_only_lighter_or_darker(shared, tmp_path, keeps_hue):
    """A red and green texture on the coloured wall, the feature losses alone (no layout, no colour transfer, no
    smoothing): keeping hue, every splat's colour moves by the same amount in R, G and B (Adam steps equal
    gradients equally), though it moves; without, the loss tints it (its channels move apart)."""
    from gt2gs_blender.core.api import transfer

    scene, cam = coloured_wall(), front_camera(96)
    texture = np.zeros((64, 64, 3), np.float32)
    texture[:, ::8, 0], texture[:, 4::8, 1] = 1.0, 1.0
    config = wall_config(
        shared,
        tmp_path,
        layout=False,
        color_transfer=False,
        lambda_tv=0.0,
        stylise_steps=6,
        correct_steps=0,
        skip_hidden=False,
        texture_keeps_hue=keeps_hue,
    )
    result = transfer(scene, texture, [cam], config).scene
    assert len(result) == len(scene)
    moved = result.base_colors - scene.base_colors
    apart = (moved - moved.mean(-1, keepdim=True)).abs().max()
    assert float(moved.abs().max()) > 1e-3
    if keeps_hue:
        assert float(apart) < 1e-5
    else:
        assert float(apart) > 1e-3
