"""*No New Hues*: the run may lighten and darken each splat, its hue only between the laid-out texture's and its own."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from gt2gs_blender.core.transfer.hue_path import along_hue_path, off_path, onto_hue_path
from gt2gs_blender.core.transfer.tone import chroma, luma

from .test_layout import front_camera, wall_config
from .test_texture_keeps_hue import coloured_wall


def test_onto_hue_path_keeps_the_light_and_lands_on_the_nearest_point_of_the_way():
    """Analytic: a colour already between the two hues is unchanged; one off the way lands on the segment's nearest
    point (here the middle, by symmetry) with its luma; past either end, on that end's hue; a way of length zero is its
    start's hue."""
    start = torch.tensor([[0.6, 0.4, 0.4]] * 4)  # reddish
    own = torch.tensor([[0.4, 0.4, 0.6]] * 4)  # bluish
    a, b = chroma(start), chroma(own)
    middle = 0.5 * (a + b)
    normal = torch.tensor([[-(b - a)[0, 1], (b - a)[0, 0]]])
    y = torch.tensor([0.3, 0.5, 0.45, 0.55])
    wanted = torch.stack([middle[0], middle[0] + 0.2 * normal[0], a[0] - (b - a)[0], b[0] + 0.5 * (b - a)[0]])

    def colour(y: torch.Tensor, c: torch.Tensor) -> torch.Tensor:
        red, blue = y + c[:, 0], y + c[:, 1]
        return torch.stack([red, (y - 0.2126 * red - 0.0722 * blue) / 0.7152, blue], -1)

    given = colour(y, wanted)
    out = onto_hue_path(given, start, own)
    assert torch.allclose(luma(out), y, atol=1e-6)
    expected = torch.stack([middle[0], middle[0], a[0], b[0]])
    assert torch.allclose(chroma(out), expected, atol=1e-6)
    assert torch.allclose(out[0], given[0], atol=1e-6)
    flat = onto_hue_path(given, start, start)
    assert torch.allclose(chroma(flat), a.expand(4, 2), atol=1e-6)


@pytest.mark.parametrize("on", [True, False])
def test_no_new_hues_keeps_every_splat_s_hue_between_its_start_and_its_own(shared, tmp_path, on):
    """A red and green texture laid on the coloured wall (no split, so rows match): with No New Hues every splat's
    hue after the run lies on the way from its laid-out start's to its own, though the run moved its colours; without,
    the steps leave some splats off that way."""
    from gt2gs_blender.core.api import transfer

    scene, cam = coloured_wall(), front_camera(96)
    texture = np.zeros((64, 64, 3), np.float32)
    texture[:, ::8, 0], texture[:, 4::8, 1] = 1.0, 1.0
    settings = dict(split_first=False, split_size=0.0, color_transfer=False, correct_steps=0, skip_hidden=False)
    start = transfer(scene, texture, [cam], wall_config(shared, tmp_path, stylise_steps=0, **settings)).scene
    config = wall_config(shared, tmp_path, stylise_steps=6, hue_on_path=on, **settings)
    result = transfer(scene, texture, [cam], config).scene
    assert len(result) == len(start) == len(scene)
    assert float((result.base_colors - start.base_colors).abs().max()) > 1e-3
    off = off_path(chroma(result.base_colors), chroma(start.base_colors), chroma(scene.base_colors.clamp(0.0, 1.0)))
    if on:
        assert float(off.max()) < 1e-5
    else:
        assert float(off.max()) > 1e-3


def test_along_hue_path_keeps_only_even_pushes_and_moves_along_the_way():
    """Analytic: an even push (1, 1, 1) and a push along the way pass unchanged; a push across the way is taken out;
    at the way's start a push that would step back past it loses its move along the way; on a way of length zero only
    the even part is left. A plain step with what is left, from a colour on the way, stays on it."""
    start = torch.tensor([[0.6, 0.4, 0.4]])
    own = torch.tensor([[0.4, 0.4, 0.6]])
    middle = 0.5 * (start + own)
    even = torch.ones(1, 3)
    assert torch.allclose(along_hue_path(even, middle, start, own), even, atol=1e-6)
    way = own - start  # (-0.2, 0, 0.2): sums to zero, so its chroma is the way and its light stays
    assert torch.allclose(along_hue_path(way, middle, start, own), way, atol=1e-6)
    across = torch.cross(even, way, dim=-1)  # orthogonal to both: off the way
    assert torch.allclose(along_hue_path(across, middle, start, own), torch.zeros(1, 3), atol=1e-6)
    back_past_start = along_hue_path(way + even, start, start, own)  # descent -grad leads from start away from own
    assert torch.allclose(back_past_start, even, atol=1e-6)
    assert torch.allclose(along_hue_path(-way + even, start, start, own), -way + even, atol=1e-6)
    assert torch.allclose(along_hue_path(way + across + even, middle, start, start), even, atol=1e-6)
    generator = torch.Generator().manual_seed(0)
    grad = torch.randn(64, 3, generator=generator)
    starts, owns = torch.rand(64, 3, generator=generator), torch.rand(64, 3, generator=generator)
    on_way = onto_hue_path(torch.rand(64, 3, generator=generator), starts, owns)
    stepped = on_way - 1e-3 * along_hue_path(grad, on_way, starts, owns)
    assert float(off_path(chroma(stepped), chroma(starts), chroma(owns)).max()) < 1e-5
