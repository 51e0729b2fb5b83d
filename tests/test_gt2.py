"""GT² geometry: rotation between views, prior angles carried across views, matching with a prior."""

from __future__ import annotations

import itertools
import math

import cv2
import numpy as np
import pytest
import torch

from gt2gs_blender.core.cameras.camera import Camera
from gt2gs_blender.core.render import render
from gt2gs_blender.core.scene.gaussians import GaussianScene
from gt2gs_blender.core.transfer.gt2 import (
    Match,
    angle_distance,
    distortion,
    fit_linear_maps,
    match_with_prior,
    prior_link,
    rotation_angle,
    view_order,
)
from gt2gs_blender.core.transfer.texture_bank import TextureBank

SIZE = 96
FOCAL = 80.0
WALL_Z = 3.0


def wall(n: int = 90) -> GaussianScene:
    """An opaque wall of n x n small flat Gaussians on z = 3 with a smooth, non-symmetric pattern."""
    coords = torch.linspace(-3.0, 3.0, n)
    y, x = torch.meshgrid(coords, coords, indexing="ij")
    means = torch.stack([x, y, torch.full_like(x, WALL_Z)], -1).reshape(-1, 3)
    spacing = float(coords[1] - coords[0])
    scales = torch.tensor([spacing * 0.6, spacing * 0.6, 1e-3]).expand(n * n, 3)
    px, py = means[:, 0], means[:, 1]
    colors = torch.stack(
        [
            0.5 + 0.4 * torch.sin(4 * px + 1.3 * py),
            0.5 + 0.4 * torch.cos(3 * py - 0.5 * px),
            0.5 + 0.3 * torch.sin(2.5 * px * py),
        ],
        -1,
    )
    return GaussianScene.from_activated(means, scales, torch.full((n * n,), 0.99), colors)


def camera(roll_deg: float = 0.0, shift: tuple[float, float] = (0.0, 0.0)) -> Camera:
    """Looking down +z at the wall from the origin plane, rolled about the optical axis, shifted in x/y."""
    r = math.radians(roll_deg)
    roll = np.array([[math.cos(r), -math.sin(r), 0.0], [math.sin(r), math.cos(r), 0.0], [0.0, 0.0, 1.0]])
    return Camera.from_cam_to_world(roll, [shift[0], shift[1], 0.0], FOCAL, FOCAL, SIZE / 2, SIZE / 2, SIZE, SIZE)


def rendered(scene: GaussianScene, cam: Camera):
    out = render(scene, [cam])
    return out.colors[0], out.depths[0], out.alphas[0]


def test_rotation_angle_follows_the_texture_bank_convention():
    """The map from a view to the one before, when the current view shows the previous image turned
    by alpha with cv2 (the bank's rotation), has rotation angle alpha."""
    rng = np.random.default_rng(0)
    for alpha in (0.0, 30.0, 170.0, -100.0, 359.0):
        rotation = cv2.getRotationMatrix2D((10.0, 7.0), alpha, 1.0)
        previous = rng.uniform(0, 20, size=(40, 2))
        current = previous @ rotation[:, :2].T + rotation[:, 2]
        maps, _, count = fit_linear_maps(
            torch.tensor(current), torch.tensor(previous), torch.zeros(40, dtype=torch.long), torch.ones(40), 1
        )
        assert int(count[0]) == 40
        assert float(angle_distance(rotation_angle(maps), torch.tensor([alpha], dtype=maps.dtype))[0]) < 1e-6


def test_fit_linear_maps_recovers_affine_maps_per_cell_and_skips_degenerate_cells():
    g = torch.Generator().manual_seed(1)
    truth = torch.randn(3, 2, 2, generator=g, dtype=torch.float64)
    src = torch.rand(90, 2, generator=g, dtype=torch.float64) * 10
    cell = torch.arange(90) % 3
    dst = (truth[cell] @ src[..., None])[..., 0] + torch.tensor([5.0, -2.0], dtype=torch.float64)
    weight = torch.ones(90)
    weight[cell == 2] = 0.0
    weight[2] = 1.0  # cell 2 keeps one point: too few to fit
    maps, _mean, count = fit_linear_maps(src, dst, cell, weight, 4)
    assert torch.allclose(maps[:2], truth[:2], atol=1e-9)
    assert count.tolist() == [30.0, 30.0, 0.0, 0.0] and maps[2:].abs().max() == 0
    # a reflection's nearest rotation is still a proper rotation
    assert torch.isfinite(rotation_angle(torch.tensor([[[1.0, 0.0], [0.0, -1.0]]], dtype=torch.float64))).all()


@pytest.mark.parametrize("roll", [25.0, -60.0, 140.0])
def test_beta_from_two_views_of_a_plane_matches_the_image_rotation(roll):
    """Issue 5: beta within 2 degrees of the known roll between two views of a textured plane; the
    oracle is the renders themselves: the second view is the first turned by beta with cv2."""
    scene = wall()
    cam0, cam1 = camera(), camera(roll)
    img0, d0, a0 = rendered(scene, cam0)
    img1, d1, a1 = rendered(scene, cam1)
    link = prior_link(cam1, d1, a1, cam0, d0, a0, (12, 12))
    rows, cols = torch.meshgrid(torch.arange(12) - 5.5, torch.arange(12) - 5.5, indexing="ij")
    assert bool(link.valid[rows.square() + cols.square() < 4.5**2].all())  # the corners turn out of view
    betas = link.beta[link.valid]
    assert (
        float(angle_distance(betas, torch.tensor(abs(roll))).min(angle_distance(betas, torch.tensor(-abs(roll)))).max())
        < 2.0
    )
    beta = float(betas.mean())
    turned = cv2.warpAffine(
        img0.numpy(), cv2.getRotationMatrix2D((SIZE / 2 - 0.5, SIZE / 2 - 0.5), beta, 1.0), (SIZE, SIZE)
    )
    wrong = cv2.warpAffine(
        img0.numpy(), cv2.getRotationMatrix2D((SIZE / 2 - 0.5, SIZE / 2 - 0.5), -beta, 1.0), (SIZE, SIZE)
    )
    centre = slice(SIZE // 2 - 20, SIZE // 2 + 20)
    err = np.abs(turned[centre, centre] - img1.numpy()[centre, centre]).mean()
    err_wrong = np.abs(wrong[centre, centre] - img1.numpy()[centre, centre]).mean()
    assert err < 0.03 and err_wrong > 3 * err


def test_prior_angles_carried_exactly_on_a_shifted_plane():
    """Sliding the camera by exactly 2 feature cells: each cell's prior is the angle of the cell 2
    columns over in the previous view, plus beta = 0, wrapped to [0, 360)."""
    scene = wall()
    cells = 12
    cell_world = (SIZE / cells) * WALL_Z / FOCAL  # one cell's width on the wall
    cam0, cam1 = camera(), camera(shift=(2 * cell_world, 0.0))
    _, d0, a0 = rendered(scene, cam0)
    _, d1, a1 = rendered(scene, cam1)
    link = prior_link(cam1, d1, a1, cam0, d0, a0, (cells, cells))
    previous = torch.arange(cells * cells, dtype=torch.float32).reshape(cells, cells) * 7.0 + 300.0
    prior = link.prior_angles(previous)
    inner = (slice(None), slice(0, cells - 2))
    expected = torch.remainder(previous[:, 2:], 360.0)
    assert bool(link.valid[inner].all()) and not bool(link.valid[:, -1].any())
    assert torch.allclose(prior[inner], expected, atol=1e-3)
    assert link.beta[link.valid].abs().max() < 1e-3
    assert torch.isnan(prior[:, -1]).all()
    assert float(prior[link.valid].min()) >= 0.0 and float(prior[link.valid].max()) < 360.0


def test_occluded_cells_get_no_prior():
    """A second, nearer wall hides part of the plane from the previous view only."""
    far = wall()
    blocker = wall(20)
    blocker = GaussianScene.from_activated(
        blocker.means * torch.tensor([0.15, 0.6, 0.0]) + torch.tensor([0.9, 0.0, 1.0]),
        blocker.scales * 0.3,
        torch.full((len(blocker),), 0.99),
        torch.zeros(len(blocker), 3),
    )
    from gt2gs_blender.core.scene.gaussians import concat

    cam0, cam1 = camera(shift=(0.5, 0.0)), camera(shift=(-0.5, 0.0))
    both = concat([far, blocker])
    _, d0, a0 = rendered(both, cam0)
    _, d1, a1 = rendered(far, cam1)  # the current view sees the far wall only (as if the blocker moved)
    link = prior_link(cam1, d1, a1, cam0, d0, a0, (12, 12))
    assert 0 < int(link.valid.sum()) < 144 - 12  # the blocked part and the edge lose their prior


def test_angle_distance_wraps():
    a = torch.tensor([359.0, 0.0, 10.0, 180.0, 720.0])
    b = torch.tensor([1.0, 360.0, 350.0, 0.0, 90.0])
    assert angle_distance(a, b).tolist() == [2.0, 0.0, 20.0, 180.0, 90.0]


def tiny_bank() -> TextureBank:
    """Three features: row 0 at theta 0, row 1 at 90, row 2 at 355; row 2 nearly equals row 0."""
    feats = torch.tensor([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.99, 0.14, 0.0]])
    return TextureBank(
        feats, torch.zeros(3, dtype=torch.long), torch.tensor([0.0, 90.0, 355.0]), (1.0,), (0.0, 90.0, 355.0), 1, "test"
    )


def test_matching_with_a_prior_trades_cosine_for_angle_and_wraps():
    bank = tiny_bank()
    query = torch.tensor([0.99, 0.14, 0.0]).reshape(3, 1, 1)  # equal to row 2 (theta 355)
    free = match_with_prior(query, bank, torch.full((1, 1), math.nan), 1.0)
    assert int(free.indices) == 2 and int(free.free_angles) == 355
    # prior 2 degrees: row 0 (2 away) beats row 2 (7 away across 0/360) at 0.01 per degree
    near_zero = match_with_prior(query, bank, torch.full((1, 1), 2.0), 0.01)
    assert int(near_zero.indices) == 0 and float(near_zero.free_angles) == 355.0
    # prior 357: row 2 (2 away, cosine distance 0) beats row 0 (3 away across 360, distance 0.01)
    assert int(match_with_prior(query, bank, torch.full((1, 1), 357.0), 0.01).indices) == 2
    # prior 358.5: row 0 (1.5 away) wins despite the worse cosine
    assert int(match_with_prior(query, bank, torch.full((1, 1), 358.5), 0.01).indices) == 0
    # a hard prior (the authors' 100 per degree) takes the prior's angle whatever the cosine
    assert int(match_with_prior(query, bank, torch.full((1, 1), 88.0), 100.0).indices) == 1


def test_matching_respects_depth_groups():
    bank = TextureBank(
        torch.eye(3), torch.tensor([0, 1, 1]), torch.tensor([0.0, 0.0, 90.0]), (1.0, 0.5), (0.0, 90.0), 1, "test"
    )
    feats = torch.tensor([[1.0, 0.0], [0.0, 0.0], [0.0, 1.0]]).reshape(3, 1, 2)  # cells: row 0, row 2
    out = match_with_prior(feats, bank, torch.full((1, 2), math.nan), 0.0, groups=torch.tensor([[1, 0]]))
    assert out.indices.tolist() == [[1, 0]]  # each cell restricted to its group's rows


def test_distortion_folds_half_turns():
    def phi(a: float, b: float) -> float:
        m = Match(torch.zeros(1), torch.tensor([a]), torch.tensor([b]))
        return float(distortion(m)[0])

    assert phi(10.0, 10.0) == 0.0 and phi(0.0, 90.0) == 1.0 and phi(0.0, 180.0) == 0.0
    assert phi(350.0, 35.0) == pytest.approx(0.5)


def test_view_order_chains_neighbours():
    angles = np.linspace(0, 2 * np.pi, 8, endpoint=False)
    ring = [
        Camera.from_cam_to_world(np.eye(3), [3 * np.cos(t), 3 * np.sin(t), 0.0], 50, 50, 32, 32, 64, 64) for t in angles
    ]
    shuffled = [ring[i] for i in (0, 5, 2, 7, 1, 4, 6, 3)]
    order = view_order(shuffled)
    positions = [(0, 5, 2, 7, 1, 4, 6, 3)[i] for i in order]
    steps = {(b - a) % 8 for a, b in itertools.pairwise(positions)}
    assert order[0] == 0 and sorted(order) == list(range(8)) and steps <= {1, 7}
