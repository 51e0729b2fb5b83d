"""Front views for a capture given without its cameras: the point its cameras stood at, read from its splats' sizes
(``fitted_viewpoint``), and the arc of views on that side (``auto_views(kind="front")``), on synthetic captures whose
cameras are known and on turned copies."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from gt2gs_blender.core.cameras.generate import FRONT_ARC_DEG, auto_views
from gt2gs_blender.core.cameras.viewpoint import MIN_GAIN, MIN_SPLATS, fitted_viewpoint
from gt2gs_blender.core.errors import GT2GSError
from gt2gs_blender.core.scene.gaussians import GaussianScene
from gt2gs_blender.core.transfer.config import TransferConfig
from gt2gs_blender.core.transfer.plan import plan_run

CAMERAS_AT = np.array([0.4, -3.0, 0.3])
"""Where the synthetic capture's cameras stood: in front of it, on -Y, a little up and to the right."""
FOOTPRINT = 0.004
"""A splat's size per unit of distance from the cameras (a pixel's footprint)."""


def front_capture(n: int = 6000, seed: int = 0, faint_share: float = 0.0) -> GaussianScene:
    """A capture seen from ``CAMERAS_AT``: a wall at y = 2 and a plant-like cluster before it, each splat sized
    ``FOOTPRINT`` x its distance from the cameras (log-normal noise, 5 % of them huge, as a trainer's background
    blobs are), ``faint_share`` of them faint and of random size."""
    rng = np.random.default_rng(seed)
    wall = np.column_stack([rng.uniform(-2, 2, n // 2), rng.uniform(1.8, 2.2, n // 2), rng.uniform(-1.5, 1.5, n // 2)])
    plant = rng.normal([0.0, 0.5, -0.3], [0.5, 0.4, 0.6], size=(n - n // 2, 3))
    means = np.concatenate([wall, plant])
    size = FOOTPRINT * np.linalg.norm(means - CAMERAS_AT, axis=1) * np.exp(rng.normal(0.0, 0.15, n))
    size[rng.random(n) < 0.05] *= 20.0
    opacity = np.full(n, 0.9)
    faint = rng.random(n) < faint_share
    opacity[faint], size[faint] = 0.1, rng.uniform(0.001, 0.5, faint.sum())
    scales = np.column_stack([size, size * 0.7, size * 0.2])
    return GaussianScene.from_activated(
        torch.from_numpy(means),
        torch.from_numpy(scales),
        torch.from_numpy(opacity),
        torch.rand(n, 3, dtype=torch.float64),
    )


def angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return math.degrees(math.acos(np.clip(a @ b / (np.linalg.norm(a) * np.linalg.norm(b)), -1.0, 1.0)))


def test_the_fit_finds_the_side_the_cameras_stood_on_and_how_far() -> None:
    """Sizes that grow with the distance from a point give that point back (outliers and faint splats aside), and
    a gain that tells (above ``MIN_GAIN``; one size for all's is under 0.05, below), though the capture's depth spans
    under half the cameras' distance and the sizes' own noise is as large as the distance's effect."""
    scene = front_capture(faint_share=0.2)
    viewpoint = fitted_viewpoint(scene)
    assert viewpoint is not None
    assert angle_deg(viewpoint.point - viewpoint.middle, CAMERAS_AT - viewpoint.middle) < 4.0
    assert np.linalg.norm(viewpoint.point - CAMERAS_AT) < 0.08 * np.linalg.norm(CAMERAS_AT - viewpoint.middle)
    assert viewpoint.gain > 1.5 * MIN_GAIN and viewpoint.telling


def test_a_moved_copy_is_fitted_again_not_answered_from_the_last_fit() -> None:
    """The fit is kept by the splats' content: the same capture read again gives the same answer, a copy moved by
    one unit gives a point moved by one unit."""
    scene = front_capture(n=3000)
    first = fitted_viewpoint(scene)
    assert fitted_viewpoint(scene.clone()) is first
    moved = scene.clone()
    moved.means.add_(torch.tensor([1.0, 0.0, 0.0], dtype=torch.float64))
    np.testing.assert_allclose(fitted_viewpoint(moved).point, first.point + np.array([1.0, 0.0, 0.0]), atol=1e-3)
    with pytest.raises(ValueError):
        first.point[0] = 0.0


def one_size_capture(n: int = 4000) -> GaussianScene:
    """Splats all of about one size: what a capture seen all round looks like to the fit."""
    rng = np.random.default_rng(1)
    means = torch.from_numpy(rng.normal(size=(n, 3)))
    scales = torch.full((n, 3), 0.02, dtype=torch.float64) * torch.from_numpy(np.exp(rng.normal(0, 0.1, (n, 1))))
    return GaussianScene.from_activated(means, scales, torch.full((n,), 0.9, dtype=torch.float64), torch.rand(n, 3))


def test_splats_of_one_size_say_nothing_and_too_few_say_nothing_at_all() -> None:
    """One size for all: the distance explains nothing (gain near 0, not telling); under ``MIN_SPLATS`` opaque
    splats, or none with a finite size, there is no fit."""
    viewpoint = fitted_viewpoint(one_size_capture())
    assert viewpoint is not None and viewpoint.gain < 0.05 and not viewpoint.telling
    few = front_capture(n=MIN_SPLATS - 1)
    assert fitted_viewpoint(few) is None
    broken = front_capture(n=200)
    broken.log_scales[:] = float("nan")
    assert fitted_viewpoint(broken) is None


def test_front_views_stand_where_the_cameras_could_have_been() -> None:
    """Every front view stands on the cameras' side, within the arc's half width of their direction, upright (the
    image's up is +Z's side), and looks at the capture's middle. The orbit's views go behind the wall."""
    scene = front_capture()
    cameras = auto_views(scene, 8, width=96, height=96, kind="front", up="+z")
    middle = fitted_viewpoint(scene).middle
    for cam in cameras:
        assert angle_deg(cam.center - middle, CAMERAS_AT - middle) < FRONT_ARC_DEG / 2 + 8.0
        _, down, forward = cam.cam_to_world[:3, :3].T
        assert down @ [0.0, 0.0, 1.0] < -0.9
        assert angle_deg(forward, middle - cam.center) < 10.0
    orbit = auto_views(scene, 8, width=96, height=96, kind="orbit", up="+z")
    assert max(angle_deg(cam.center - middle, CAMERAS_AT - middle) for cam in orbit) > 150.0


def test_a_capture_whose_sizes_do_not_tell_gets_the_arc_on_blender_s_front() -> None:
    """Where the sizes say nothing (the robot's fitted point lay under its ground, gain 0.04), Front views are the
    arc on Blender's front, not views from wherever the fit landed."""
    scene = one_size_capture()
    front = auto_views(scene, 5, width=64, height=64, kind="front", up="+z")
    for mine, arc in zip(front, auto_views(scene, 5, width=64, height=64, kind="arc", up="+z"), strict=True):
        np.testing.assert_allclose(mine.cam_to_world, arc.cam_to_world)


def test_an_up_along_the_look_is_replaced_by_one_across_it() -> None:
    """A capture lying flat in its file (the fern's thinnest axis is its depth, so its up is found along the look):
    the views stay upright about a trainer's -Y, the first world axis across the look."""
    scene = front_capture()
    turned = GaussianScene.from_activated(
        scene.means[:, [0, 2, 1]] * torch.tensor([1.0, -1.0, 1.0], dtype=torch.float64),
        scene.scales,
        scene.opacities.reshape(-1),
        scene.base_colors,
    )  # y -> z, z -> -y: the cameras now stand on -Z, and -Y is up
    cameras = auto_views(turned, 5, width=64, height=64, kind="front", up="+z")
    for cam in cameras:
        down = cam.cam_to_world[:3, 1]
        assert down @ [0.0, -1.0, 0.0] < -0.9
        assert cam.center[2] < -1.0


def test_splats_at_one_point_are_framed_from_outside_their_footprint() -> None:
    """Front views of splats at one point (nothing to read, no extent) frame their footprint as the orbit does."""
    n = 50
    scene = GaussianScene.from_activated(
        torch.full((n, 3), 2.0), torch.full((n, 3), 0.05), torch.full((n,), 0.9), torch.rand(n, 3)
    )
    for cam in auto_views(scene, 4, width=64, height=64, kind="front"):
        assert np.linalg.norm(cam.center - 2.0) > 3 * 0.05


def test_the_run_plans_front_views_when_asked_and_refuses_an_unknown_kind() -> None:
    """``view_kind="front"`` reaches the run's cameras (all on the cameras' side); a kind that is none of the
    choices is refused by the config."""
    scene = front_capture(n=3000).to(dtype=torch.float32)
    texture = np.random.default_rng(0).random((64, 64, 3))
    config = TransferConfig(view_kind="front", n_views=4, resolution=64, up="+z", device="cpu", backend="torch")
    plan = plan_run(scene, texture, None, config, preview=True)
    middle = fitted_viewpoint(scene).middle
    assert all(angle_deg(cam.center - middle, CAMERAS_AT - middle) < 30.0 for cam in plan.cameras)
    with pytest.raises((GT2GSError, ValueError), match="view_kind"):
        TransferConfig(view_kind="spiral")
