"""The run's automatic views cut to the splats (``cut_to_points``): the same pixels where they overlap, the whole
object inside, the empty bands of a tall or wide object's square frame gone."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from gt2gs_blender.core.api import read_scene, render
from gt2gs_blender.core.cameras.cut import CUT_STEP, cut_to_points
from gt2gs_blender.core.cameras.generate import auto_views
from gt2gs_blender.core.cameras.poses import look_at
from gt2gs_blender.core.scene.gaussians import GaussianScene
from gt2gs_blender.core.transfer.views import fit_cameras

from .conftest import SHARED

SIDE = 128


def capture(name: str) -> GaussianScene:
    """A shared scene at SH degree 0, skipped when the shared folder is not there."""
    path = SHARED / "data" / "scenes" / name
    if not path.exists():
        pytest.skip(f"scene not found at {path}")
    return read_scene(path).with_sh_degree(0).detach()


def test_a_cut_camera_sees_the_same_pixels_where_the_two_overlap() -> None:
    """``Camera.cropped``: a world point lands on the same pixel less the cut, each side cut by half the difference."""
    cam = look_at((0.3, -4.0, 1.0), (0.0, 0.0, 0.0), width=200, height=120, fov_deg=50.0)
    cut = cam.cropped(160, 64)
    points = np.random.default_rng(0).normal(size=(20, 3))
    np.testing.assert_allclose(cut.project(points)[0], cam.project(points)[0] - [20.0, 28.0], atol=1e-9)
    assert (cut.fx, cut.fy, cut.width, cut.height) == (cam.fx, cam.fy, 160, 64)


@pytest.mark.parametrize("name, least_cut", [("captures/guitar.compressed.ply", 0.45), ("donut/point_cloud.ply", 0.3)])
def test_the_run_s_views_hold_the_whole_object_and_the_square_views_pixels(name: str, least_cut: float) -> None:
    """Rendered from the run's cut views, the guitar (tall) and the donut (wide) give the square views' renders cut
    about their centres, pixel for pixel, and keep all but a trace of their alpha: the cut only drops empty
    bands, and it drops at least ``least_cut`` of the pixels."""
    scene = capture(name)
    square = auto_views(scene, 4, width=SIDE, height=SIDE, up="auto")
    cut = fit_cameras(scene, 4, SIDE, 4, "auto", cut=True)
    width, height = cut[0].width, cut[0].height
    assert all((c.width, c.height) == (width, height) for c in cut)
    assert 1.0 - width * height / SIDE**2 >= least_cut
    assert (SIDE - width) % (2 * CUT_STEP) == 0 and (SIDE - height) % (2 * CUT_STEP) == 0
    full = render(scene, square, background=(1.0, 1.0, 1.0), render_depth=False)
    kept = render(scene, cut, background=(1.0, 1.0, 1.0), render_depth=False)
    top, left = (SIDE - height) // 2, (SIDE - width) // 2
    inside = full.alphas[:, top : top + height, left : left + width]
    torch.testing.assert_close(kept.alphas, inside, atol=1e-5, rtol=0.0)
    colours = full.colors[:, top : top + height, left : left + width]
    torch.testing.assert_close(kept.colors, colours, atol=1e-3, rtol=0.0)  # blend order of equal depths
    assert float(inside.sum()) >= 0.999 * float(full.alphas.sum())


def test_a_view_is_never_grown_nor_cut_when_the_points_fill_it_or_stand_behind_it() -> None:
    """Points beyond the frame leave the views as they were; points all behind the cameras too."""
    cams = [look_at((0.0, -4.0, 0.0), (0.0, 0.0, 0.0), width=64, height=48)]
    wide = np.array([[-50.0, 0.0, -50.0], [50.0, 0.0, 50.0]])
    behind = np.array([[0.0, -10.0, 0.0], [1.0, -9.0, 0.5]])
    for points in (wide, behind):
        (same,) = cut_to_points(cams, points)
        assert (same.width, same.height, same.cx, same.cy) == (64, 48, 32.0, 24.0)


def test_a_few_floaters_do_not_decide_the_cut() -> None:
    """A tight cluster with a handful of far floaters is cut to the cluster: ``CUT_SHARE`` of the points decides."""
    rng = np.random.default_rng(1)
    cluster = rng.normal(scale=0.1, size=(5000, 3))
    floaters = np.array([[2.0, 0.0, 0.0], [-2.0, 0.0, 1.5], [0.0, 0.0, -2.0]])
    cams = [look_at((0.0, -4.0, 0.0), (0.0, 0.0, 0.0), width=256, height=256)]
    (alone,) = cut_to_points(cams, cluster)
    (with_floaters,) = cut_to_points(cams, np.concatenate([cluster, floaters]))
    assert (with_floaters.width, with_floaters.height) == (alone.width, alone.height)
    assert alone.width < 128 and alone.height < 128


def test_a_large_cloud_is_cut_from_a_sample_as_from_all_its_points(monkeypatch: pytest.MonkeyPatch) -> None:
    """Past ``CUT_SAMPLE`` centres the cut reads an even stride of them: a 300,000-point elongated cloud (ordered
    along its length, as a file sorted in space would be) gets the cut that all of its points give."""
    from gt2gs_blender.core.cameras import cut

    rng = np.random.default_rng(2)
    cloud = rng.normal(scale=(0.1, 0.1, 0.5), size=(300_000, 3))
    cloud = cloud[np.argsort(cloud[:, 2])]
    cams = ring_views()
    sampled = cut_to_points(cams, cloud)
    monkeypatch.setattr(cut, "CUT_SAMPLE", len(cloud))
    whole = cut_to_points(cams, cloud)
    assert [(c.width, c.height) for c in sampled] == [(c.width, c.height) for c in whole]
    assert sampled[0].width < 256 and sampled[0].height <= 256


def ring_views() -> list:
    """Four 256 px views on a ring about +z, 4 units out, looking at the origin."""
    return [
        look_at((4.0 * np.cos(a), 4.0 * np.sin(a), 1.0), (0.0, 0.0, 0.0), width=256, height=256)
        for a in np.linspace(0.0, 2.0 * np.pi, 4, endpoint=False)
    ]
