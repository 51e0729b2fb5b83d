"""Views for a capture seen from inside (a room) given without its cameras: the fit of where its cameras stood
(``fitted_viewpoint``) says they stood within it, and the automatic views stand there looking out
(``auto_views(kind="inside")``, what *Auto* picks), on synthetic rooms whose cameras are known, turned copies of
them, and the shared captures, which are objects and keep their ring."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import torch

from gt2gs_blender.core.cameras.generate import INSIDE_PITCH_DEG, auto_views, chosen_kind, inside_point
from gt2gs_blender.core.cameras.poses import outward_views
from gt2gs_blender.core.cameras.viewpoint import EMPTY_RADIUS, EMPTY_SHARE, INSIDE_CORE, fitted_viewpoint
from gt2gs_blender.core.fit.init import scene_from_points
from gt2gs_blender.core.scene.files import read_scene
from gt2gs_blender.core.scene.gaussians import GaussianScene
from gt2gs_blender.core.transfer.config import TransferConfig
from gt2gs_blender.core.transfer.plan import plan_run

SHARED = Path(__file__).resolve().parents[2] / "shared" / "data" / "scenes"
EYE = np.array([0.3, -0.4, 1.5])
"""Where the synthetic room's cameras stood: near its middle, at eye height."""
ROOM = (np.array([-2.5, -2.0, 0.0]), np.array([2.5, 2.0, 2.6]))
FOOTPRINT = 0.004
"""A splat's size per unit of distance from the cameras (a pixel's footprint)."""


def room(n: int = 8000, seed: int = 0, ceiling: bool = True) -> GaussianScene:
    """A 5 x 4 x 2.6 room (+Z up) seen from ``EYE``: splats on its walls, floor and (``ceiling``) ceiling, each
    ``FOOTPRINT`` x its distance from the cameras (log-normal noise, 5 % of them huge, as a trainer's blobs are)."""
    rng = np.random.default_rng(seed)
    lo, hi = ROOM
    faces = [(axis, side) for axis in (0, 1) for side in (lo, hi)] + [(2, lo)] + ([(2, hi)] if ceiling else [])
    per = n // len(faces)
    means = []
    for axis, side in faces:
        points = rng.uniform(lo, hi, size=(per, 3))
        points[:, axis] = side[axis] + rng.normal(0.0, 0.02, per)
        means.append(points)
    means = np.concatenate(means)
    size = FOOTPRINT * np.linalg.norm(means - EYE, axis=1) * np.exp(rng.normal(0.0, 0.15, len(means)))
    size[rng.random(len(means)) < 0.05] *= 20.0
    return GaussianScene.from_activated(
        torch.from_numpy(means),
        torch.from_numpy(np.column_stack([size, size * 0.7, size * 0.2])),
        torch.full((len(means),), 0.9, dtype=torch.float64),
        torch.rand(len(means), 3, dtype=torch.float64),
    )


def looks(cam) -> np.ndarray:
    """The direction a camera looks along (world)."""
    return cam.cam_to_world[:3, 2]


@pytest.mark.parametrize("ceiling", [True, False])
def test_a_room_reads_as_seen_from_inside_and_where_its_cameras_stood(ceiling: bool) -> None:
    """Sizes that grow with the distance from a point within the room give that point back to a few centimetres,
    fitted from the room's middle, and say the capture was taken from inside, with or without a ceiling: *Auto*
    picks the inside views."""
    scene = room(ceiling=ceiling)
    viewpoint = fitted_viewpoint(scene)
    assert viewpoint is not None and viewpoint.inside
    assert np.linalg.norm(viewpoint.point - EYE) < 0.05
    assert chosen_kind(scene, "auto") == "inside"
    np.testing.assert_allclose(inside_point(scene), viewpoint.point)


def test_inside_views_stand_where_the_cameras_stood_and_see_the_room_all_round() -> None:
    """Every automatic view of the room stands at its cameras' point, looks out level but ``INSIDE_PITCH_DEG``
    down, upright, the views evenly all round, and together they see nearly every wall splat from in front; a
    ring from outside looks at the walls' backs from beyond them."""
    scene = room().to(dtype=torch.float32)
    cameras = auto_views(scene, 8, width=32, height=32, kind="auto", up="+z")
    azimuths = []
    for cam in cameras:
        assert np.linalg.norm(cam.center - EYE) < 0.05
        forward, down = looks(cam), cam.cam_to_world[:3, 1]
        assert math.degrees(math.asin(-forward[2])) == pytest.approx(INSIDE_PITCH_DEG, abs=1e-6)
        assert down @ [0.0, 0.0, 1.0] < -0.9
        azimuths.append(math.degrees(math.atan2(forward[1], forward[0])))
    steps = np.diff(np.unwrap(np.radians(azimuths)))
    np.testing.assert_allclose(np.degrees(steps), 45.0, atol=1e-6)
    walls = scene.means.detach().double().numpy()
    walls = walls[(walls[:, 2] > 0.2) & (walls[:, 2] < 2.4)]
    seen = np.zeros(len(walls), dtype=bool)
    for cam in cameras:
        uv, depth = cam.project(walls)
        framed = (depth > 0) & np.all((uv >= 0) & (uv <= [cam.width, cam.height]), axis=1)
        assert framed.mean() > 0.03
        seen |= framed
    assert seen.mean() > 0.95
    lo, hi = ROOM
    for cam in auto_views(scene, 8, width=32, height=32, kind="orbit", up="+z"):
        assert np.any((cam.center < lo) | (cam.center > hi))


def test_a_turned_room_gets_the_same_views_turned() -> None:
    """A copy of the room lying as a trainer writes it (-Y up) gets the original's views carried by the same turn."""
    scene = room(n=4000)
    turn = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])  # +Z -> -Y
    turned = GaussianScene.from_activated(
        scene.means @ torch.from_numpy(turn).T,
        scene.scales,
        scene.opacities.reshape(-1),
        scene.base_colors,
    )
    original = auto_views(scene, 6, width=32, height=32, kind="auto", up="+z")
    copy = auto_views(turned, 6, width=32, height=32, kind="auto", up="-y")
    for mine, theirs in zip(original, copy, strict=True):
        np.testing.assert_allclose(turn @ mine.center, theirs.center, atol=1e-3)
        np.testing.assert_allclose(turn @ looks(mine), looks(theirs), atol=1e-3)


def test_a_garden_walked_round_its_table_keeps_its_ring() -> None:
    """Mip-NeRF 360's garden (an eighth of its SfM points made splats, sized by their neighbours as a fit starts
    them): its sizes tell (gain over 0.1), but not that its cameras stood inside it: *Auto* keeps the ring; its
    middle, where a room's fit starts, holds its table, not air (``EMPTY_SHARE``)."""
    path = SHARED / "garden_points" / "test_garden.npz"
    if not path.is_file():
        pytest.skip(f"garden points not found at {path}")
    garden = np.load(path)
    every = slice(None, None, 8)  # 17,346 of its 138,766 points: sized by their neighbours in seconds
    scene = scene_from_points(
        torch.from_numpy(garden["means3d"][every].astype(np.float64)),
        torch.from_numpy(garden["colors"][every].astype(np.float64)).clamp(0.0, 1.0),
        opacity=0.9,
    )
    viewpoint = fitted_viewpoint(scene)
    assert viewpoint.telling and not viewpoint.inside and chosen_kind(scene, "auto") == "orbit"
    means = scene.means.detach().numpy()
    lo, hi = np.quantile(means, [0.02, 0.98], axis=0)
    near = np.linalg.norm(means - (lo + hi) / 2.0, axis=1) < EMPTY_RADIUS * np.linalg.norm(hi - lo)
    assert near.mean() > EMPTY_SHARE


def test_a_point_among_splats_is_not_where_cameras_stood() -> None:
    """The room with a dense cluster round its cameras' point (a third of its splats within 0.3 m, sized by their
    distance like the rest): the fit still lands there, in the core, walls all round, but no camera stands inside
    something: *Auto* keeps the ring."""
    rng = np.random.default_rng(3)
    walls = room(n=6000)
    cluster = torch.from_numpy(EYE + rng.normal(0.0, 0.1, size=(3000, 3)))
    size = FOOTPRINT * (cluster - torch.from_numpy(EYE)).norm(dim=1, keepdim=True).clamp_min(0.01)
    crowded = GaussianScene.from_activated(
        torch.cat([walls.means, cluster]),
        torch.cat([walls.scales, size * torch.tensor([1.0, 0.7, 0.2], dtype=torch.float64)]),
        torch.cat([walls.opacities.reshape(-1), torch.full((3000,), 0.9, dtype=torch.float64)]),
        torch.cat([walls.base_colors, torch.rand(3000, 3, dtype=torch.float64)]),
    )
    viewpoint = fitted_viewpoint(crowded)
    lo, hi = ROOM
    assert viewpoint.telling and np.linalg.norm(viewpoint.point - EYE) < 0.2
    assert np.all(np.abs(viewpoint.point - (lo + hi) / 2.0) < INSIDE_CORE * (hi - lo))
    assert not viewpoint.inside and chosen_kind(crowded, "auto") == "orbit"


def test_a_room_whose_sizes_do_not_tell_is_seen_from_its_middle_when_asked() -> None:
    """Splats of one size say nothing of where the cameras stood: *Auto* keeps the ring, and *Inside*, asked,
    stands in the middle of the splats' robust bounds."""
    scene = room(n=4000)
    scene.log_scales[:] = math.log(0.01)
    assert chosen_kind(scene, "auto") == "orbit"
    lo, hi = (b.numpy() for b in scene.bounds(0.98))
    for cam in auto_views(scene, 4, width=32, height=32, kind="inside", up="+z"):
        np.testing.assert_allclose(cam.center, (lo + hi) / 2.0)


@pytest.mark.parametrize("path", ["donut/point_cloud.ply", "captures/guitar.compressed.ply"])
def test_the_shared_objects_keep_their_ring(path: str) -> None:
    """The donut and the guitar, objects seen all round, do not read as seen from inside: *Auto* draws exactly the
    orbit's views."""
    scene = read_scene(SHARED / path)
    assert chosen_kind(scene, "auto") == "orbit"
    for auto, orbit in zip(auto_views(scene, 4, kind="auto"), auto_views(scene, 4, kind="orbit"), strict=True):
        np.testing.assert_array_equal(auto.cam_to_world, orbit.cam_to_world)


def test_outward_views_are_ordered_counter_clockwise_from_the_front() -> None:
    """The first view looks along ``first`` (+Y, as Blender's Front view and the orbit's first view look); the next
    ones turn counter-clockwise seen from ``up``; bad counts and pitches are refused."""
    cams = outward_views((1.0, 2.0, 3.0), 4, width=16, height=16, pitch_deg=0.0, up=(0, 0, 1))
    np.testing.assert_allclose([looks(c) for c in cams], [[0, 1, 0], [-1, 0, 0], [0, -1, 0], [1, 0, 0]], atol=1e-12)
    orbit_first = auto_views(room(n=2000), 4, width=16, height=16, kind="orbit", up="+z")[0]
    inside_first = auto_views(room(n=2000), 4, width=16, height=16, kind="inside", up="+z")[0]
    assert looks(inside_first)[:2] @ looks(orbit_first)[:2] > 0.9 * np.linalg.norm(looks(orbit_first)[:2])
    assert all(np.allclose(c.center, (1.0, 2.0, 3.0)) for c in cams)
    with pytest.raises(ValueError, match="at least one view"):
        outward_views((0, 0, 0), 0, width=16, height=16)
    with pytest.raises(ValueError, match="pitch_deg"):
        outward_views((0, 0, 0), 2, width=16, height=16, pitch_deg=90.0)


def test_the_run_plans_inside_views_for_a_room_by_default() -> None:
    """A room given without cameras: the run's own cameras (today's default *Auto*) stand inside it, and the
    automatic projection wraps the texture round it (Box), as for an object seen all round."""
    scene = room(n=4000).to(dtype=torch.float32)
    texture = np.random.default_rng(0).random((64, 64, 3))
    config = TransferConfig(n_views=4, resolution=64, up="+z", device="cpu", backend="torch")
    assert config.view_kind == "auto"
    plan = plan_run(scene, texture, None, config, preview=True)
    lo, hi = ROOM
    assert all(np.all((cam.center > lo) & (cam.center < hi)) for cam in plan.cameras)
    assert (plan.config.view_kind, plan.config.layout_projection, plan.config.stylise_geometry) == (
        "inside",
        "box",
        "off",
    )
