"""The synthetic captures' tracer (``bench/traced.py``) against distances worked out by hand: a room seen from
inside, a box before its wall, and rays that meet nothing."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))
sys.path.insert(0, str(ROOT))

from traced import Box, one_look, trace

from gt2gs_blender.core.cameras.poses import look_at

PLASTER = 0.88
"""The colour of a face with no texture."""
SHELL = Box((-1.0, -2.0, -1.0), (3.0, 2.0, 1.0), one_look(None, 1.0, (0.5, 0.6, 0.7)), shell=True)
BLOCK = Box((1.0, -0.25, -0.25), (1.5, 0.25, 0.25), one_look(None, 1.0, (0.9, 0.8, 0.7)))


def _centre_ray(boxes: list[Box], background: float = 0.0) -> tuple[np.ndarray, float]:
    """The colour and depth at the middle of a 33 x 33 view from the origin looking along +X."""
    cam = look_at((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), width=33, height=33, fov_deg=40.0)
    colour, depth = trace(cam, boxes, 33, 33, background=background)
    return colour[16, 16], float(depth[16, 16])


def test_a_room_seen_from_inside_ends_at_the_wall_it_looks_at() -> None:
    """From the origin along +X the shell's far wall stands 3 m away, shaded as an X face."""
    colour, depth = _centre_ray([SHELL])
    assert abs(depth - 3.0) < 1e-9
    np.testing.assert_allclose(colour, PLASTER * 0.5)


def test_a_box_before_the_wall_hides_it() -> None:
    """A solid box 1 m out meets the ray at its near face, in the box's own shade, whatever order the boxes come in."""
    for boxes in ([SHELL, BLOCK], [BLOCK, SHELL]):
        colour, depth = _centre_ray(boxes)
        assert abs(depth - 1.0) < 1e-9
        np.testing.assert_allclose(colour, PLASTER * 0.9)


def test_rays_that_meet_nothing_see_the_background_at_no_depth() -> None:
    """Rays past the box (its sides seen from outside only) keep the background and an infinite depth; the box's
    own pixels are at the distances of its face."""
    cam = look_at((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), width=33, height=33, fov_deg=40.0)
    colour, depth = trace(cam, [BLOCK], 33, 33, background=0.25)
    hit = np.isfinite(depth)
    assert hit[16, 16] and not hit[0, 0]
    np.testing.assert_allclose(colour[~hit], 0.25)
    rays = np.linalg.norm(np.stack(np.meshgrid(np.arange(33) - 16.0, np.arange(33) - 16.0), -1), axis=-1)
    focal = cam.fx
    expected = np.sqrt(1.0 + (rays / focal) ** 2)  # the near face at x = 1 along each pixel's centre ray
    np.testing.assert_allclose(depth[hit], expected[hit], rtol=1e-9)
