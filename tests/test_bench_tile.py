"""bench/transfer.py's ``--tile``: a larger capture made of copies of a real one, side by side."""

from __future__ import annotations

import sys
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.common import random_scene
from bench.transfer import tiled


def test_tiled_copies_lie_side_by_side_without_overlap() -> None:
    """Six copies: six times the splats, each copy the original moved along the two widest axes only, and
    no two copies' 98 % bounds overlap along the axis they are laid on."""
    scene = random_scene(500, degree=1)
    scene.means[:, 2] *= 0.1  # a flat capture: x and y are the widest axes
    copies = tiled(scene, 6)
    assert len(copies) == 6 * len(scene)
    low, high = scene.bounds(0.99)
    offsets = []
    for k in range(6):
        part = copies.subset(slice(k * len(scene), (k + 1) * len(scene)))
        offset = part.means - scene.means
        assert torch.allclose(offset, offset[:1].expand_as(offset), atol=1e-5)
        assert float(offset[0, 2]) == 0.0
        for name in ("quats", "log_scales", "opacity_logits", "sh_dc", "sh_rest"):
            assert torch.equal(getattr(part, name), getattr(scene, name))
        offsets.append(offset[0])
    width = high - low
    for i in range(6):
        for j in range(i + 1, 6):
            gap = (offsets[i] - offsets[j]).abs()
            assert bool((gap[:2] >= width[:2]).any())


def test_one_tile_is_the_scene_itself() -> None:
    """``--tile 1`` (the default) runs the file as it is."""
    scene = random_scene(50, degree=0)
    assert tiled(scene, 1) is scene
