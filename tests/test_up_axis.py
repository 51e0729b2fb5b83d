"""The automatic views' up axis, found from the splats (``estimate_up_axis``) on real captures and turned copies."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

from gt2gs_blender.core.api import read_scene, render
from gt2gs_blender.core.cameras.axes import axis_vector, up_from_rotation
from gt2gs_blender.core.cameras.generate import auto_views
from gt2gs_blender.core.cameras.up import estimate_up_axis, front_for
from gt2gs_blender.core.scene.gaussians import GaussianScene

QUARTER_TURN_X = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
"""A quarter turn about +X: takes +Y to +Z, so a trainer's -Y-up capture to a -Z-up copy and its inverse to +Z-up."""


def turned(scene: GaussianScene, rotation: np.ndarray) -> GaussianScene:
    """``scene`` turned by ``rotation`` about the origin (centres and orientations; SH degree 0, view-independent)."""
    r = torch.tensor(rotation, dtype=scene.dtype)
    w = np.sqrt(max(1.0 + np.trace(rotation), 0.0)) / 2.0
    x, y, z = (rotation[2, 1] - rotation[1, 2], rotation[0, 2] - rotation[2, 0], rotation[1, 0] - rotation[0, 1])
    q = torch.tensor([w, x / (4 * w), y / (4 * w), z / (4 * w)], dtype=scene.dtype)
    a, b = q, scene.quats.detach()
    product = torch.stack(
        [
            a[0] * b[:, 0] - a[1] * b[:, 1] - a[2] * b[:, 2] - a[3] * b[:, 3],
            a[0] * b[:, 1] + a[1] * b[:, 0] + a[2] * b[:, 3] - a[3] * b[:, 2],
            a[0] * b[:, 2] - a[1] * b[:, 3] + a[2] * b[:, 0] + a[3] * b[:, 1],
            a[0] * b[:, 3] + a[1] * b[:, 2] - a[2] * b[:, 1] + a[3] * b[:, 0],
        ],
        dim=1,
    )
    return replace(scene.with_sh_degree(0).detach(), means=scene.means.detach() @ r.T, quats=product)


@pytest.fixture(scope="module")
def guitar() -> GaussianScene:
    path = Path(__file__).resolve().parents[2] / "shared" / "data" / "scenes" / "captures" / "guitar.compressed.ply"
    if not path.is_file():
        pytest.skip(f"capture not found at {path}")
    return read_scene(path).with_sh_degree(0).detach()


def centres(scene: GaussianScene) -> np.ndarray:
    """The splat centres inside the scene's robust bounds (what ``auto_views`` estimates from)."""
    lo, hi = (b.detach().double().numpy() for b in scene.bounds(0.98))
    means = scene.means.detach().double().numpy()
    return means[np.all((means >= lo) & (means <= hi), axis=1)]


def test_a_trainer_s_guitar_stands_on_its_stand_whichever_way_the_file_turns_it(guitar: GaussianScene) -> None:
    """The guitar (a trainer's capture: up is -Y, its stand's feet at +Y) is found standing, and so are copies turned
    to +Z and -Z up: a tall, flat object, whose thinnest axis (the body's thickness) is not its up."""
    np.testing.assert_array_equal(estimate_up_axis(centres(guitar)), [0.0, -1.0, 0.0])
    for rotation, up in ((QUARTER_TURN_X, [0.0, 0.0, -1.0]), (QUARTER_TURN_X.T, [0.0, 0.0, 1.0])):
        np.testing.assert_array_equal(estimate_up_axis(centres(turned(guitar, rotation))), up)


def test_a_y_up_and_a_z_up_copy_of_a_capture_get_the_same_views(guitar: GaussianScene) -> None:
    """Automatic views with ``up="auto"`` on the guitar and on its copy turned to +Z up see the same images: the up
    axis and the ring's first direction turn with the capture."""
    z_up = turned(guitar, QUARTER_TURN_X.T)
    images = []
    for scene in (guitar, z_up):
        cameras = auto_views(scene, 4, width=64, height=64, up="auto")
        images.append(render(scene, cameras, background=(1.0, 1.0, 1.0), render_depth=False).colors)
    assert float((images[0] - images[1]).abs().max()) < 2e-3
    upright = images[0][0]
    rows = (upright < 0.9).any(dim=(1, 2)).nonzero()[:, 0]
    cols = (upright < 0.9).any(dim=(0, 2)).nonzero()[:, 0]
    assert int(rows.max() - rows.min()) > 2 * int(cols.max() - cols.min())  # the tall guitar stands in the image


def test_the_ring_s_front_turns_with_the_up_axis() -> None:
    """``front_for``: Blender's front (-Y) for +Z, carried by the quarter turn that takes +Z to each other axis."""
    for up in ([0, 0, 1], [0, 0, -1], [0, 1, 0], [0, -1, 0], [1, 0, 0], [-1, 0, 0]):
        front = front_for(up)
        assert abs(front @ up) < 1e-12 and np.linalg.norm(front) == pytest.approx(1.0)
    np.testing.assert_array_equal(front_for([0, 0, 1]), [0, -1, 0])
    np.testing.assert_array_equal(front_for(QUARTER_TURN_X @ [0, 0, 1.0]), QUARTER_TURN_X @ [0, -1.0, 0])
    np.testing.assert_array_equal(front_for(QUARTER_TURN_X.T @ [0, 0, 1.0]), QUARTER_TURN_X.T @ [0, -1.0, 0])


def test_a_ground_patch_under_an_object_says_which_way_is_up() -> None:
    """A flat patch of ground with a small object standing on it, along -Y as a trainer writes it: up is -Y from
    the support, whatever the convention would say, and +Y when the same scene is mirrored."""
    rng = np.random.default_rng(3)
    ground = rng.uniform(-1.0, 1.0, size=(4000, 3)) * [1.0, 0.01, 1.0] + [0.0, 0.3, 0.0]
    robot = rng.normal(size=(1000, 3)) * [0.1, 0.15, 0.1] + [0.0, 0.1, 0.0]
    points = np.concatenate([ground, robot])
    np.testing.assert_array_equal(estimate_up_axis(points), [0.0, -1.0, 0.0])
    np.testing.assert_array_equal(estimate_up_axis(points * [1.0, -1.0, 1.0]), [0.0, 1.0, 0.0])


def test_a_garden_stands_on_its_lawn_as_its_real_cameras_say() -> None:
    """Mip-NeRF 360's garden (its SfM points and three of its real cameras, from gsplat's test data): up is +Z, the
    cameras' own up, not the edge where a sparse ring of tree tops spreads wider than the lawn; a copy turned to a
    trainer's -Y up finds -Y."""
    path = Path(__file__).resolve().parents[2] / "shared" / "data" / "scenes" / "garden_points" / "test_garden.npz"
    if not path.is_file():
        pytest.skip(f"garden points not found at {path}")
    garden = np.load(path)
    points = garden["means3d"].astype(np.float64)
    lo, hi = np.quantile(points, [0.01, 0.99], axis=0)
    points = points[np.all((points >= lo) & (points <= hi), axis=1)]
    cameras_up = -garden["viewmats"][:, 1, :3].mean(axis=0)  # a camera's up is its -Y row
    np.testing.assert_array_equal(np.round(cameras_up / np.linalg.norm(cameras_up)), [0.0, 0.0, 1.0])
    np.testing.assert_array_equal(estimate_up_axis(points), [0.0, 0.0, 1.0])
    np.testing.assert_array_equal(estimate_up_axis(points @ QUARTER_TURN_X.T), [0.0, -1.0, 0.0])


def test_the_run_plan_reports_the_up_axis_it_found(guitar: GaussianScene) -> None:
    """A plan with ``up`` auto and automatic views resolves it to the axis found (the guitar's -Y), for the report;
    given cameras keep it as asked (they need none)."""
    from gt2gs_blender.core.api import preset
    from gt2gs_blender.core.transfer.plan import plan_run

    texture = np.full((32, 32, 3), 0.5, np.float32)
    config = preset("preview", n_views=2, resolution=32, layout=False, texture_repeats=0.0)
    plan = plan_run(guitar, texture, None, config, preview=True)
    assert plan.asked.up == "auto" and plan.resolved()["up"] == "-y"
    given = plan_run(guitar, texture, plan.cameras, config, preview=True)
    assert given.resolved()["up"] == "auto"


def _turn(axis: int, degrees: float) -> np.ndarray:
    """The rotation by ``degrees`` about world axis ``axis`` (0: X, 1: Y, 2: Z), right-handed."""
    c, s = np.cos(np.radians(degrees)), np.sin(np.radians(degrees))
    i, j = (axis + 1) % 3, (axis + 2) % 3  # the cyclic pair: (y, z) for X, (z, x) for Y, (x, y) for Z
    r = np.eye(3)
    r[i, i], r[i, j], r[j, i], r[j, j] = c, -s, s, c
    return r


@pytest.mark.parametrize(
    ("axis", "degrees", "up"),
    [(0, 90, "+y"), (0, -90, "-y"), (0, 180, "-z"), (1, 90, "-x"), (1, -90, "+x"), (0, 80, "+y"), (2, 90, None)],
)
def test_an_object_stood_upright_in_blender_says_which_of_its_axes_is_up(axis, degrees, up) -> None:
    """The object's own axis its turn brings to world +Z, by name, within 25°, whatever its scale; a turn about
    +Z alone leaves +Z up, which the splats decide."""
    r = _turn(axis, degrees)
    assert up_from_rotation(r) == up
    assert up_from_rotation(r * np.array([2.0, 0.5, 3.0])) == up  # the object's scale, column by column
    if up is not None:
        assert np.allclose(r @ np.array(axis_vector(up)), [0.0, 0.0, 1.0], atol=0.2)


@pytest.mark.parametrize("degrees", [0.0, 10.0, 45.0, -30.0])
def test_an_object_tilted_but_not_stood_on_another_axis_leaves_up_to_the_splats(degrees) -> None:
    """Unturned, tilted a little about its +Z-ish pose, or turned halfway between two axes: no answer."""
    assert up_from_rotation(_turn(0, degrees)) is None
