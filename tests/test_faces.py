"""Box Fits Faces: the box layout turns about up onto an object's own faces, whatever way its file turns it."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import torch

from gt2gs_blender.core.api import read_scene
from gt2gs_blender.core.cameras.generate import auto_views
from gt2gs_blender.core.cameras.poses import look_at
from gt2gs_blender.core.scene.gaussians import GaussianScene
from gt2gs_blender.core.transfer.config import TransferConfig
from gt2gs_blender.core.transfer.faces import FACES_CONCENTRATION, faces_direction
from gt2gs_blender.core.transfer.layout import layout_colours, layout_frame, splat_normals
from gt2gs_blender.core.transfer.views import ViewSet, render_views

from .test_layout import stripes
from .test_up_axis import turned

SIDES = 40


def flat_splats(means: torch.Tensor, angles: torch.Tensor, spacing: float) -> GaussianScene:
    """Opaque grey splats at ``means``, each flat across the direction ``angles`` (radians about +Y from +Z)."""
    n = len(means)
    scene = GaussianScene.from_activated(
        means,
        torch.tensor([spacing * 0.7, spacing * 0.7, 1e-3]).expand(n, 3),
        torch.full((n,), 0.99),
        torch.full((n, 3), 0.5),
    )
    quats = torch.stack([torch.cos(angles / 2), torch.zeros(n), torch.sin(angles / 2), torch.zeros(n)], dim=1)
    return replace(scene, quats=quats)


def box_sides(turn_deg: float) -> GaussianScene:
    """The four sides of a 2-unit box about the origin (no lid or floor), turned ``turn_deg`` about +Y."""
    coords = torch.linspace(-1.0, 1.0, SIDES)
    v, u = (t.reshape(-1, 1) for t in torch.meshgrid(coords, coords, indexing="ij"))
    means, angles = [], []
    for side in range(4):
        a = math.radians(turn_deg + 90.0 * side)
        normal, across = torch.tensor([math.sin(a), 0.0, math.cos(a)]), torch.tensor([math.cos(a), 0.0, -math.sin(a)])
        means.append(normal + u * across + v * torch.tensor([0.0, 1.0, 0.0]))
        angles.append(torch.full((SIDES * SIDES,), a))
    return flat_splats(torch.cat(means), torch.cat(angles), 2.0 / (SIDES - 1))


def drum(n_around: int = 160) -> GaussianScene:
    """A round drum's side (radius 1, 2 units tall): no face stands out."""
    a = torch.linspace(0.0, 2 * math.pi, n_around + 1)[:-1].repeat_interleave(SIDES)
    y = torch.linspace(-1.0, 1.0, SIDES).repeat(n_around)
    means = torch.stack([torch.sin(a), y, torch.cos(a)], dim=1)
    return flat_splats(means, a, 2.0 * math.pi / n_around)


def ring_views(scene: GaussianScene, size: int = 96) -> ViewSet:
    """Eight views round +Y from slightly above, the first on +X (world-fixed, as the automatic ring is)."""
    cameras = [
        look_at(
            (6 * math.cos(a), 2.0, 6 * math.sin(a)),
            (0.0, 0.0, 0.0),
            width=size,
            height=size,
            fov_deg=40.0,
            up=(0.0, -1.0, 0.0),
        )
        for a in np.linspace(0.0, 2 * math.pi, 8, endpoint=False)
    ]
    return render_views(scene, cameras, torch.ones(3), "auto")


def heading_deg(v: np.ndarray) -> float:
    """The direction of a horizontal vector about +Y, in degrees from +Z toward +X (as the sides' normals turn)."""
    return math.degrees(math.atan2(v[0], v[2]))


def apart_deg(a: float, b: float) -> float:
    """How far apart two directions stand (degrees) when a quarter turn counts as none (a box's four sides)."""
    return abs((a - b + 45.0) % 90.0 - 45.0)


@pytest.mark.parametrize("turn", [0.0, 20.0, 45.0, 70.0])
def test_the_box_turns_onto_a_box_s_sides(turn):
    """The box's right lies along one of the sides' directions with Box Fits Faces, wherever the file turns the box;
    without it, along the first view's right (+Z here) however the sides stand."""
    scene = box_sides(turn)
    views = ring_views(scene)
    first = layout_frame(scene, views, TransferConfig(box_fits_faces=False))
    np.testing.assert_allclose(first.axes[0], [0.0, 0.0, 1.0], atol=1e-6)
    angle, concentration = faces_direction(views, first.axes)
    assert concentration > 0.8
    assert apart_deg(-math.degrees(angle), turn) < 1.0  # measured from right (+Z) toward depth (-X, the first view's)
    fitted = layout_frame(scene, views, TransferConfig())
    assert apart_deg(heading_deg(fitted.axes[0]), turn) < 1.0
    assert abs(faces_direction(views, fitted.axes)[0]) < math.radians(1.0)
    np.testing.assert_allclose(np.abs(fitted.axes @ fitted.axes.T), np.eye(3), atol=1e-9)  # still a frame


def test_a_side_at_45_degrees_reads_the_texture_once():
    """Bars laid on a box turned 45° to the first view: each side between two of the box's planes read both, out of
    step (the bars' contrast halved on two sides); turned to the sides, every side reads one plane, bars at full
    contrast."""
    scene = box_sides(45.0)
    views = ring_views(scene)
    contrast = {}
    for fits in (False, True):
        frame = layout_frame(scene, views, TransferConfig(texture_repeats=2.0, box_fits_faces=fits))
        colours = layout_colours(scene, splat_normals(scene, views, frame), stripes(32, 128), frame, 0.0)
        contrast[fits] = colours.mean(1).reshape(4, -1).std(1)
    assert float(contrast[True].min()) > 0.4  # black and white bars: 0.5 at most
    assert float(contrast[False].min()) < 0.3


def test_a_round_object_keeps_the_first_view_s_box():
    """A drum's side faces every way alike: no direction stands out and the box stays as the first view stands."""
    scene = drum()
    views = ring_views(scene)
    first = layout_frame(scene, views, TransferConfig(box_fits_faces=False))
    assert faces_direction(views, first.axes)[1] < FACES_CONCENTRATION / 4
    np.testing.assert_array_equal(layout_frame(scene, views, TransferConfig()).axes, first.axes)


def test_a_turned_guitar_gets_the_box_its_own_body_gets(shared):
    """The real guitar, and a copy its file turns 30° about its up (-Y): turned to its faces, the box stands the
    same way on the guitar in both (within 2°, a side's direction either way), where the first view's box turns
    with the file."""
    guitar = read_scene(shared / "data" / "scenes" / "captures" / "guitar.compressed.ply").with_sh_degree(0).detach()
    a = math.radians(30.0)
    turn = np.array([[math.cos(a), 0.0, math.sin(a)], [0.0, 1.0, 0.0], [-math.sin(a), 0.0, math.cos(a)]])
    rights = {}
    for name, scene, back in (("as filed", guitar, np.eye(3)), ("turned", turned(guitar, turn), turn)):
        cameras = auto_views(scene, 16, width=128, height=128, up="-y")
        views = render_views(scene, cameras, torch.ones(3), "auto")
        for fits in (False, True):
            axes = layout_frame(scene, views, TransferConfig(texture_repeats=1.5, box_fits_faces=fits)).axes
            rights[name, fits] = back.T @ axes[0]  # in the guitar's own frame as filed
    filed, turned_back = (heading_deg(rights[name, True]) for name in ("as filed", "turned"))
    assert apart_deg(filed, turned_back) < 2.0
    assert apart_deg(heading_deg(rights["as filed", False]), heading_deg(rights["turned", False])) > 20.0
