"""The texture layout (core/transfer/layout.py) against analytic cases: a plane's normals, the split's children
against their parent (the float64 reference renderer, numeric integration), the projection's period and angle,
and the bank's tiling of small textures."""

from __future__ import annotations

import itertools
import math
from dataclasses import replace

import numpy as np
import pytest
import torch

from gt2gs_blender.core.cameras.camera import Camera
from gt2gs_blender.core.render import render
from gt2gs_blender.core.scene.gaussians import GaussianScene, quats_to_rotmats
from gt2gs_blender.core.transfer.config import TransferConfig
from gt2gs_blender.core.transfer.detail import SPLIT_OFFSET, SPLIT_SHRINK, child_opacity, split_coarse
from gt2gs_blender.core.transfer.layout import (
    layout_colours,
    layout_frame,
    layout_images,
    texture_height_for,
    with_colours,
)
from gt2gs_blender.core.transfer.normals import surface_normals
from gt2gs_blender.core.transfer.texture_bank import build_texture_bank, crop_side, tiled_for_crop
from gt2gs_blender.core.transfer.views import render_views

from .reference import render_reference


def wall(n: int = 60, tilt_deg: float = 0.0) -> GaussianScene:
    """A flat grey wall of n x n Gaussians 3 units in front of the origin, turned ``tilt_deg`` about y."""
    coords = torch.linspace(-1.0, 1.0, n)
    y, x = torch.meshgrid(coords, coords, indexing="ij")
    t = math.radians(tilt_deg)
    means = torch.stack([x * math.cos(t), y, 3.0 + x * math.sin(t)], -1).reshape(-1, 3)
    spacing = float(coords[1] - coords[0])
    half = torch.tensor([math.cos(t / 2), 0.0, math.sin(t / 2), 0.0])  # (w, x, y, z) about y
    scene = GaussianScene.from_activated(
        means,
        torch.tensor([spacing * 0.7, spacing * 0.7, 1e-3]).expand(n * n, 3),
        torch.full((n * n,), 0.99),
        torch.full((n * n, 3), 0.5),
    )
    return GaussianScene(
        means=scene.means,
        quats=half.expand(n * n, 4).clone(),
        log_scales=scene.log_scales,
        opacity_logits=scene.opacity_logits,
        sh_dc=scene.sh_dc,
        sh_rest=scene.sh_rest,
    )


def front_camera(size: int = 96) -> Camera:
    """Looking down +z from the origin (OpenCV axes: x right, y down)."""
    return Camera.from_cam_to_world(np.eye(3), [0.0, 0.0, 0.0], size * 0.9, size * 0.9, size / 2, size / 2, size, size)


@pytest.mark.parametrize("tilt", [0.0, 35.0])
def test_normals_of_a_wall_are_its_plane_normal(tilt):
    """Every splat the view sees gets the wall's normal; the rest the nearest seen one's (the same here)."""
    scene = wall(tilt_deg=tilt)
    cam = front_camera()
    out = render(scene, [cam])
    normals = surface_normals(scene, [cam], [out.depths[0]], [out.alphas[0]])
    expected = torch.tensor([-math.sin(math.radians(tilt)), 0.0, math.cos(math.radians(tilt))])
    cosines = (normals @ expected).abs()
    assert float(torch.quantile(cosines, 0.05)) > math.cos(math.radians(8.0))


def test_split_children_sit_about_their_parent():
    """The 2 x 2 children sit at +-``SPLIT_OFFSET`` sigma along the parent's two largest axes, around its mean,
    with ``SPLIT_SHRINK`` of those scales, its smallest kept, and ``child_opacity`` squared of its opacity."""
    g = torch.Generator().manual_seed(0)
    n = 50
    parent = GaussianScene.from_activated(
        torch.randn(n, 3, generator=g),
        torch.rand(n, 3, generator=g) * 0.2 + 0.05,
        torch.rand(n, generator=g) * 0.98 + 0.01,
        torch.rand(n, 3, generator=g),
    )
    parent = replace(parent, quats=torch.randn(n, 4, generator=g))
    children, source = split_coarse(parent, max_sigma=0.0, max_count=4 * n)
    assert len(children) == 4 * n and torch.equal(torch.sort(source).values, torch.arange(n).repeat_interleave(4))
    rot = quats_to_rotmats(parent.rotations)
    for i in range(n):
        kids = source == i
        ordered, axes = parent.scales[i].sort(descending=True)
        local = (children.means[kids] - parent.means[i]) @ rot[i][:, axes]  # along the largest, middle, smallest
        assert torch.allclose(local.mean(0), torch.zeros(3), atol=1e-5)
        assert torch.allclose(
            local.abs(), (SPLIT_OFFSET * ordered * torch.tensor([1.0, 1.0, 0.0])).expand(4, 3), atol=1e-5
        )
        shrunk = ordered * torch.tensor([SPLIT_SHRINK, SPLIT_SHRINK, 1.0])
        assert torch.allclose(children.scales[kids][:, axes], shrunk.expand(4, 3), rtol=1e-5)
        wanted = parent.opacities[i] * child_opacity() ** 2
        assert torch.allclose(children.opacities[kids], wanted.expand(4), rtol=1e-5)


def test_child_opacity_is_the_least_squares_fit_of_faint_children():
    """The closed form against numeric integration: the share of opacity that brings two faint children's
    summed alpha closest to their parent's (a Gaussian of unit sigma), on a fine grid."""
    x = np.linspace(-6.0, 6.0, 601)
    xs, ys = np.meshgrid(x, x)
    parent = np.exp(-0.5 * (xs**2 + ys**2))
    pair = sum(np.exp(-0.5 * (((xs - side * SPLIT_OFFSET) / SPLIT_SHRINK) ** 2 + ys**2)) for side in (-1, 1))
    assert child_opacity() == pytest.approx(float((parent * pair).sum() / (pair * pair).sum()), rel=1e-6)
    assert child_opacity(0.0, 1.0) == pytest.approx(0.5)  # two copies of the parent: half its opacity each


def face_on_splat(opacity: float, scales: list[float]) -> GaussianScene:
    """One splat 5 units in front of :data:`FACE_ON`, its two largest axes in the image plane."""
    return GaussianScene.from_activated(
        torch.tensor([[0.0, 0.0, 5.0]]), torch.tensor([scales]), torch.tensor([opacity]), torch.full((1, 3), 0.5)
    )


FACE_ON = np.array([[100.0, 0.0, 64.0], [0.0, 100.0, 64.0], [0.0, 0.0, 1.0]])
"""128 px intrinsics for the identity view: a 0.3 sigma splat at depth 5 spans 6 px a sigma."""


def reference_alpha(scene: GaussianScene) -> np.ndarray:
    """The float64 reference renderer's alpha of ``scene`` from the identity view (:data:`FACE_ON`)."""
    with torch.no_grad():
        args = [t.double().numpy() for t in (scene.means, scene.quats, scene.scales, scene.opacities)]
    return render_reference(*args, scene.base_colors.double().numpy(), np.eye(4), FACE_ON, 128, 128).alpha


def moment_split(parent: GaussianScene, n_axes: int) -> GaussianScene:
    """The split as it was: children at 0.8 sigma, 0.6 of the scale, the parent's opacity (its second moment)."""
    sides = list(itertools.product((-1.0, 1.0), repeat=n_axes))
    scales = parent.scales[0].clone()
    offsets = torch.zeros(len(sides), 3)
    offsets[:, :n_axes] = 0.8 * torch.tensor(sides) * scales[:n_axes]
    scales[:n_axes] *= 0.6
    return GaussianScene.from_activated(
        parent.means + offsets,
        scales.expand(len(sides), 3),
        parent.opacities.expand(len(sides)),
        parent.base_colors.expand(len(sides), 3),
    )


@pytest.mark.parametrize("opacity", [0.1, 0.5, 0.9])
@pytest.mark.parametrize(("scales", "n_axes", "limit"), [([0.3, 0.3, 0.01], 2, 0.22), ([0.3, 0.05, 0.01], 1, 0.16)])
def test_split_children_render_like_their_parent(opacity, scales, n_axes, limit):
    """Rendered by the float64 reference, one split's children draw their parent's alpha within ``limit`` (relative
    L2; the best share for this placement reaches 0.14 and 0.10 on a faint splat), under half the error of the
    second-moment split they replace (0.53-0.55 and 0.31-0.33, its children too opaque and two-humped)."""
    parent = face_on_splat(opacity, scales)
    children, _ = split_coarse(parent, max_sigma=0.25, max_count=100)
    assert len(children) == 2**n_axes
    drawn = reference_alpha(parent)
    error = np.linalg.norm(reference_alpha(children) - drawn) / np.linalg.norm(drawn)
    before = np.linalg.norm(reference_alpha(moment_split(parent, n_axes)) - drawn) / np.linalg.norm(drawn)
    assert error <= limit and error <= 0.5 * before


def test_a_needle_splits_along_its_length_only():
    """A splat coarse along one axis only halves along it (1 x 2): the children keep its width, so they grow
    rounder instead of thinner, sit at +-``SPLIT_OFFSET`` sigma along it and keep ``child_opacity`` of its
    opacity."""
    angle = 0.4
    quat = torch.tensor([[math.cos(angle / 2), 0.0, 0.0, math.sin(angle / 2)]])  # turned about z
    needle = GaussianScene(
        means=torch.tensor([[0.1, -0.2, 0.3]]),
        quats=quat,
        log_scales=torch.log(torch.tensor([[0.4, 0.02, 0.01]])),
        opacity_logits=torch.zeros(1),
        sh_dc=torch.zeros(1, 3),
        sh_rest=torch.zeros(1, 0, 3),
    )
    once, source = split_coarse(needle, max_sigma=0.3, max_count=100)
    assert len(once) == 2 and source.tolist() == [0, 0]
    assert torch.allclose(once.scales, torch.tensor([[0.24, 0.02, 0.01]]).expand(2, 3), atol=1e-6)
    long_axis = quats_to_rotmats(quat)[0][:, 0]
    offsets = once.means - needle.means
    assert torch.allclose(offsets, torch.outer(torch.tensor([-0.24, 0.24]), long_axis), atol=1e-6)
    assert torch.allclose(once.opacities, torch.full((2,), 0.5 * child_opacity()), rtol=1e-6)
    thrice, _ = split_coarse(needle, max_sigma=0.05, max_count=100)
    assert len(thrice) == 8 and torch.allclose(thrice.scales[:, 1:], torch.tensor([0.02, 0.01]).expand(8, 2))


def test_split_stops_at_the_size_and_the_count():
    """Splits only splats above the size, and never past the count."""
    scene = wall(n=20)
    largest = float(scene.scales.max())
    kept, _ = split_coarse(scene, largest * 2, 10_000)
    assert len(kept) == len(scene)
    capped, _ = split_coarse(scene, 0.0, len(scene) + 3 * 50)
    assert len(scene) < len(capped) <= len(scene) + 3 * 50
    fine, _ = split_coarse(scene, largest * 0.5, 100_000)
    assert float(fine.scales.max(dim=1).values.max()) <= largest * 0.5 + 1e-6


def wall_config(shared, tmp_path, **overrides) -> TransferConfig:
    """A short laid-out run over the wall at 96 px (one depth group, no densification, no metrics)."""
    base = dict(
        resolution=96,
        rounds=1,
        n_scales=1,
        n_angles=8,
        layout=True,
        texture_repeats=2.0,
        densify=False,
        evaluate=False,
        weights_path=str(shared / "weights"),
        cache_dir=str(tmp_path),
    )
    return TransferConfig(**{**base, **overrides})


def stripes(period: int = 32, size: int = 128) -> np.ndarray:
    """Vertical black and white bars, ``period`` px per pair."""
    x = np.arange(size)
    row = ((x // (period // 2)) % 2).astype(np.float32)
    return np.repeat(np.repeat(row[None, :, None], size, axis=0), 3, axis=2)


@pytest.mark.parametrize("angle", [0.0, 90.0])
def test_layout_lays_the_texture_at_its_repeat_and_angle(angle):
    """A wall facing the first view shows the bars with the period the repeats ask for, turned by the angle."""
    scene = wall(n=120)
    cam = front_camera()
    views = render_views(scene, [cam], torch.ones(3), "auto")
    config = TransferConfig(texture_repeats=2.0, angle=angle)
    frame = layout_frame(scene, views, config)
    assert frame.repeat == pytest.approx(2.0 / 2.0, rel=0.05)  # a 2-unit wall seen whole, twice across
    normals = surface_normals(scene, [cam], views.depths, views.alphas)
    texture = stripes(period=32, size=128)  # 4 bar pairs per texture height
    colours = layout_colours(scene, normals, texture, frame, angle).mean(1).reshape(120, 120).numpy()
    along = colours.mean(0) if angle == 0.0 else colours.mean(1)
    across = colours.mean(1) if angle == 0.0 else colours.mean(0)
    spectrum = np.abs(np.fft.rfft(along - along.mean()))
    period_world = 2.0 / int(np.argmax(spectrum))  # the wall is 2 units across
    assert period_world == pytest.approx(frame.repeat / 4, rel=0.15)
    assert across.std() < 0.1 * along.std()  # constant along the bars


@pytest.mark.parametrize("projection", ["box", "view"])
@pytest.mark.parametrize("angle", [0.0, 90.0])
def test_texture_offset_slides_the_texture_right_and_up(projection, angle):
    """Offset Right / Up slide the laid texture as the first view sees it: by four splats' spacing, each splat
    reads what the one four to its left (or below) read; a whole repeat gives the same look."""
    n = 129  # a 2-unit wall: a spacing of 1/64
    scene, cam = wall(n=n), front_camera(128)
    views = render_views(scene, [cam], torch.ones(3), "auto")
    normals = surface_normals(scene, [cam], views.depths, views.alphas)
    texture = stripes(period=32, size=128)
    base = TransferConfig(texture_repeats=2.0, layout_projection=projection, n_scales=1, angle=angle)
    repeat = layout_frame(scene, views, base).repeat
    step = 4 * 2.0 / (n - 1) / repeat  # four splats, in repeats
    along = "texture_offset_right" if angle == 0.0 else "texture_offset_up"

    def colours(offset: float) -> torch.Tensor:
        config = replace(base, **{along: offset})
        return layout_colours(scene, normals, texture, layout_frame(scene, views, config), angle).reshape(n, n, 3)

    still, slid, whole = colours(0.0), colours(step), colours(1.0)
    assert float(still.std()) > 0.3  # bars to slide
    if angle == 0.0:  # vertical bars: x grows with the column
        torch.testing.assert_close(slid[:, 8:-8], still[:, 4:-12], atol=0.05, rtol=0.0)
    else:  # horizontal bars: the wall's y grows with the row, the first view's up is -y (OpenCV)
        torch.testing.assert_close(slid[8:-8], still[12:-4], atol=0.05, rtol=0.0)
    torch.testing.assert_close(whole, still, atol=0.02, rtol=0.0)


@pytest.mark.parametrize("projection", ["box", "view"])
def test_a_moved_capture_gets_the_same_layout(projection):
    """The texture lies on the object, not on the world's origin: the wall and its view moved far away (a
    capture with another origin) read the same colours, splat for splat (anchored at the origin, the box's
    bars moved with the world by a third of a period)."""
    texture = stripes(period=32, size=128)
    offset = np.array([1000.3, -700.1, 512.7])
    colours = []
    for shift in (np.zeros(3), offset):
        scene = wall(n=60, tilt_deg=20.0)
        scene.means = scene.means + torch.from_numpy(shift).float()
        cam = Camera.from_cam_to_world(np.eye(3), shift, 86.4, 86.4, 48.0, 48.0, 96, 96)
        views = render_views(scene, [cam], torch.ones(3), "auto")
        frame = layout_frame(scene, views, TransferConfig(texture_repeats=2.0, layout_projection=projection))
        normals = surface_normals(scene, [cam], views.depths, views.alphas)
        colours.append(layout_colours(scene, normals, texture, frame, 30.0))
    assert float(colours[0].std(0).mean()) > 0.2  # the bars are there to move
    torch.testing.assert_close(colours[1], colours[0], atol=0.02, rtol=0.0)


@pytest.mark.parametrize("tilt", [0.0, 60.0])
def test_the_view_projection_shows_the_texture_as_the_first_view_does(tilt):
    """Thrown from the first view, the bars keep their on-screen period on a wall however steeply it is
    turned (one depth group): the repeat's on-screen size at the nearest depth, 4 bar pairs per repeat."""
    scene, cam = wall(n=160, tilt_deg=tilt), front_camera(128)
    views = render_views(scene, [cam], torch.ones(3), "auto")
    config = TransferConfig(texture_repeats=2.0, layout_projection="view", n_scales=1)
    frame = layout_frame(scene, views, config)
    assert frame.projector is not None
    colours = layout_colours(scene, torch.zeros(len(scene), 3), stripes(period=32, size=128), frame, 0.0)
    out = render(with_colours(scene, colours), [cam], background=torch.ones(3))
    rows = slice(48, 80)
    covered = (out.alphas[0][rows] > 0.99).all(0).nonzero().squeeze(1).numpy()  # columns on the wall
    along = out.colors[0].mean(-1).numpy()[rows, covered[4] : covered[-4]].mean(0)
    padded = 2048  # zero padding: a finer frequency grid than the wall's few periods give
    spectrum = np.abs(np.fft.rfft(along - along.mean(), n=padded))
    repeat_px = texture_height_for(frame, views, 1) / 0.5
    assert padded / int(np.argmax(spectrum)) == pytest.approx(repeat_px / 4, rel=0.1)


def test_auto_projection_throws_from_the_view_for_captures_and_boxes_orbits():
    """``auto``: cameras that all look the same way (a capture) take the view projection, a ring the box; no
    views, or views that cancel out, are no capture."""
    from gt2gs_blender.core.cameras.poses import look_at
    from gt2gs_blender.core.cameras.spread import seen_from_front
    from gt2gs_blender.core.transfer.layout import projection

    UP = (0.0, 1.0, 0.0)
    capture = [
        look_at((x, 0.0, -3.0), (0.0, 0.0, 0.0), width=64, height=64, fov_deg=50.0, up=UP) for x in (-0.5, 0.0, 0.5)
    ]
    ring = [
        look_at((3 * math.cos(a), 0.0, 3 * math.sin(a)), (0.0, 0.0, 0.0), width=64, height=64, fov_deg=50.0, up=UP)
        for a in np.linspace(0.0, 2 * math.pi, 8, endpoint=False)
    ]
    assert projection(capture, "auto") == "view" and projection(ring, "auto") == "box"
    assert projection(ring, "view") == "view" and projection(capture, "box") == "box"
    with pytest.raises(ValueError, match="layout_projection"):
        projection(ring, "sphere")
    assert not seen_from_front(np.zeros((0, 3)), 45.0) and not seen_from_front(np.array([[0, 0, 1], [0, 0, -1]]), 45.0)


def test_texture_height_matches_the_repeat_on_screen():
    """The bank's texture height is the repeat's on-screen size at the feature scale, on the nearest surfaces."""
    scene = wall(n=60)
    cam = front_camera()
    views = render_views(scene, [cam], torch.ones(3), "auto")
    frame = layout_frame(scene, views, TransferConfig(texture_repeats=2.0))
    height = texture_height_for(frame, views, 1)
    assert height == pytest.approx(frame.repeat * cam.fy / 3.0 * 0.5, abs=1.5)
    back = layout_frame(scene, views, TransferConfig(texture_repeats=0.0, texture_height=height))
    assert back.repeat == pytest.approx(frame.repeat, rel=0.02)


def test_small_textures_are_tiled_not_refused():
    """A texture too small for the bank's crop (the 'too small for the feature bank' crash) is repeated."""
    small = stripes(period=8, size=24)
    tiled = tiled_for_crop(small, 64)
    assert crop_side(*tiled.shape[:2]) >= 64
    centre = (tiled.shape[0] - 24) // 2, (tiled.shape[1] - 24) // 2
    assert np.array_equal(tiled[centre[0] : centre[0] + 24, centre[1] : centre[1] + 24], small)
    assert tiled_for_crop(stripes(size=128), 64) is not None
    bank = build_texture_bank(
        small,
        lambda x: torch.nn.functional.avg_pool2d(x, 4),
        extractor_id="pool",
        n_scales=2,
        n_angles=4,
        texture_height=20,
        max_crop=64,
    )
    assert len(bank) == 2 * 4 * 64 and torch.isfinite(bank.features).all()


@pytest.mark.parametrize("angle", [0.0, 90.0])
def test_a_transfer_with_the_layout_keeps_the_stripes_period_and_angle(shared, tmp_path, angle):
    """End to end: bars laid on a wall come out of a (short) transfer at the repeat's period and the angle."""
    from gt2gs_blender.core.api import transfer

    scene, cam = wall(n=100), front_camera(96)
    texture = stripes(period=32, size=128)
    config = wall_config(shared, tmp_path, stylise_steps=20, correct_steps=10, angle=angle, color_transfer=False)
    result = transfer(scene, texture, [cam], config)
    assert result.report["skips"]["layout"]["split"] >= 0
    grey = render(result.scene, [cam], background=torch.ones(3)).colors[0].mean(-1).numpy()[20:-20, 20:-20]
    along, across = (grey.mean(0), grey.mean(1)) if angle == 0.0 else (grey.mean(1), grey.mean(0))
    spectrum = np.abs(np.fft.rfft(along - along.mean()))
    repeat_px = result.report["config"]["texture_height"] / 0.5  # the repeat on screen, in render pixels
    period_px = len(along) / int(np.argmax(spectrum))
    assert period_px == pytest.approx(repeat_px / 4, rel=0.2)
    assert across.std() < 0.25 * along.std()


def test_the_layout_preview_is_the_run_s_starting_point(shared, tmp_path):
    """The orientation preview with the layout on shows exactly what a run starts from (no steps)."""
    from gt2gs_blender.core.api import transfer
    from gt2gs_blender.core.transfer.orientation_preview import preview

    scene, cam = wall(n=80, tilt_deg=20.0), front_camera(96)
    texture = stripes(period=32, size=128)
    config = wall_config(
        shared, tmp_path, stylise_steps=0, correct_steps=0, texture_repeats=3.0, angle=30.0, color_transfer=False
    )
    started = transfer(scene, texture, [cam], config).scene
    expected = render(started, [cam], background=torch.ones(3)).colors[0].clamp(0, 1).numpy() * 255.0
    shown = preview(scene, texture, [cam], config, size=96)
    assert shown.splats == len(started)
    assert np.abs(shown.image.astype(np.float32) - expected).max() <= 1.0


def test_a_region_s_preview_is_the_region_run_s_starting_point(shared, tmp_path):
    """With only the wall's left half selected, the preview lays the texture on that half, sized on it, as
    the run does: the same picture as a zero-step run with that region, the right half still grey."""
    from gt2gs_blender.core.api import transfer
    from gt2gs_blender.core.transfer.orientation_preview import preview

    scene, cam = wall(n=80), front_camera(96)
    region = scene.means[:, 0] < -0.05
    texture = stripes(period=32, size=128)
    config = zero_step_config(shared, tmp_path, texture_repeats=3.0, angle=30.0)
    started = transfer(scene, texture, [cam], config, region=region).scene
    expected = render(started, [cam], background=torch.zeros(3)).colors[0].clamp(0, 1).numpy() * 255.0
    shown = preview(scene, texture, [cam], config, size=96, region=region)
    whole = preview(scene, texture, [cam], config, size=96)
    assert shown.splats == len(started) < whole.splats
    assert np.abs(shown.image.astype(np.float32) - expected).max() <= 1.0
    right = shown.image[20:-20, 60:-20].astype(np.float32)
    assert np.abs(right - 0.5 * 255).max() <= 2.0 and whole.image[20:-20, 60:-20].std() > 20


def test_the_preview_skips_the_splats_the_run_skips(shared, tmp_path):
    """Behind the wall, a coarse wall no view sees: the run leaves its splats as they are (not laid out, not
    split), and the preview counts and shows the same scene as a zero-step run, not a split of them too."""
    from gt2gs_blender.core.api import transfer
    from gt2gs_blender.core.scene.gaussians import concat
    from gt2gs_blender.core.transfer.orientation_preview import preview

    front, cam = wall(n=80), front_camera(96)
    behind = GaussianScene.from_activated(
        wall(n=6).means * torch.tensor([0.6, 0.6, 4.0 / 3.0]),
        torch.tensor([0.15, 0.15, 1e-3]).expand(36, 3),
        torch.full((36,), 0.99),
        torch.full((36, 3), 0.2),
    )
    scene = concat([front, behind])
    texture = stripes(period=32, size=128)
    config = wall_config(shared, tmp_path, stylise_steps=0, correct_steps=0, texture_repeats=3.0, color_transfer=False)
    result = transfer(scene, texture, [cam], config)
    assert result.report["skips"]["hidden"] >= len(behind)  # and the front splats other splats cover
    kept = (result.scene.means[:, 2] > 3.5).nonzero().squeeze(1)
    assert torch.equal(result.scene.subset(kept).means, behind.means)  # not split
    expected = render(result.scene, [cam], background=torch.ones(3)).colors[0].clamp(0, 1).numpy() * 255.0
    shown = preview(scene, texture, [cam], config, size=96)
    assert shown.splats == len(result.scene)
    assert np.abs(shown.image.astype(np.float32) - expected).max() <= 1.0


@pytest.mark.parametrize("split_first", [True, False])
def test_the_report_says_how_close_the_result_is_to_its_preview(shared, tmp_path, split_first):
    """A run with no steps is its preview (preview_ssim ~1), whether the run keeps its own laid-out start's view
    (split first) or lays the preview out again (split at the end); a flat grey picture of the same view is not."""
    from gt2gs_blender.core.api import transfer
    from gt2gs_blender.core.transfer.metrics import preview_ssim

    scene, cam = wall(n=80, tilt_deg=20.0), front_camera(96)
    texture = stripes(period=32, size=128)
    config = wall_config(
        shared,
        tmp_path,
        stylise_steps=0,
        correct_steps=0,
        texture_repeats=3.0,
        evaluate=True,
        color_transfer=False,
        split_first=split_first,
    )
    result = transfer(scene, texture, [cam], config)
    assert result.report["metrics"]["preview_ssim"] >= 0.99
    flat = np.full((96, 96, 3), 128, np.uint8)
    assert preview_ssim(result.scene, flat, cam, torch.ones(3)) < 0.1


def test_the_sketch_preview_takes_the_texture_size_the_run_derives(shared, tmp_path):
    """With the layout off and Texture Repeats set, the screen-space preview shows the bars at the repeat the
    run will use (not at the config's own texture height)."""
    from gt2gs_blender.core.transfer.orientation_preview import preview

    scene, cam = wall(n=100), front_camera(96)
    config = wall_config(shared, tmp_path, layout=False, texture_repeats=2.0, texture_height=256)
    image = preview(scene, stripes(period=32, size=128), [cam], config, size=96).image
    views = render_views(scene, [cam], torch.ones(3), "auto")
    height = texture_height_for(layout_frame(scene, views, config), views, config.n_scales)
    grey = image.astype(np.float32).mean(-1)[20:-20, 20:-20].mean(0)
    spectrum = np.abs(np.fft.rfft(grey - grey.mean()))
    assert height < 128 and len(grey) / int(np.argmax(spectrum)) == pytest.approx(height / 0.5 / 4, rel=0.2)


def half_dark_wall() -> tuple[GaussianScene, Camera, np.ndarray]:
    """The wall at luminance 0.2 on its left half and 0.8 on its right, its front camera, a white texture."""
    base, cam = wall(n=80), front_camera(96)
    left = base.means[:, 0] < 0
    grey = torch.where(left[:, None], torch.full((len(base), 3), 0.2), torch.full((len(base), 3), 0.8))
    return with_colours(base, grey), cam, np.ones((64, 64, 3), np.float32)


def zero_step_config(shared, tmp_path, **overrides) -> TransferConfig:
    """The wall's laid-out run with no optimisation and no colour transfer: what it lays is what comes out."""
    return wall_config(
        shared,
        tmp_path,
        stylise_steps=0,
        correct_steps=0,
        color_transfer=False,
        skip_hidden=False,
        background=(0, 0, 0),
        **overrides,
    )


@pytest.mark.parametrize("keep", [1.0, 0.5, 0.0])
def test_the_layout_keeps_the_scene_s_light_and_shade(shared, tmp_path, keep):
    """A white texture on a wall dark on its left half (luminance 0.2) and light on its right (0.8), Scene
    Softness 0 (each splat its own shade): at Keep Scene 1 the two halves keep the scene's ratio of tones, 0.2 /
    0.8, at 0.5 its square root, at 0 none (all white); the preview shows exactly the zero-step run, the detail
    split's children included."""
    from gt2gs_blender.core.api import transfer
    from gt2gs_blender.core.transfer.orientation_preview import preview

    scene, cam, white = half_dark_wall()
    config = zero_step_config(
        shared, tmp_path, keep_scene=keep, scene_colour=0.0, scene_brightness=0.0, shade_softness=0.0
    )
    result = transfer(scene, white, [cam], config)
    colours = result.scene.base_colors.mean(1)
    on_left = result.scene.means[:, 0] < -0.1
    on_right = result.scene.means[:, 0] > 0.1
    dark = (0.2 / 0.8) ** keep
    assert float(colours[on_left].mean()) == pytest.approx(dark, abs=0.02)
    assert float(colours[on_right].mean()) == pytest.approx(1.0, abs=0.02)
    expected = render(result.scene, [cam], background=torch.zeros(3)).colors[0].clamp(0, 1).numpy() * 255.0
    assert np.abs(preview(scene, white, [cam], config, size=96).image.astype(np.float32) - expected).max() <= 1.0
    # the layout term's target is shaded the same way, per pixel from the view's own luminance
    views = render_views(scene, [cam], torch.zeros(3), "auto")
    (ideal,) = layout_images(views, white, layout_frame(scene, views, config), 0.0, keep > 0, keep=keep)
    covered = ideal[..., 3] > 0
    half = torch.zeros_like(covered)
    half[:, : 96 // 2 - 6] = True  # the wall's left half on screen, away from the seam
    assert float(ideal[..., 0][covered & half].mean()) == pytest.approx(dark, abs=0.03)
    assert float(ideal[..., 0][covered & ~half].max()) == pytest.approx(1.0, abs=0.02)


@pytest.mark.parametrize("keep", [1.0, 0.0])
def test_a_whole_run_keeps_the_two_tones_of_the_scene_under_a_flat_texture(shared, tmp_path, keep):
    """The half-dark wall (luminance 0.2 and 0.8) under a flat mid-grey texture, a whole short run with every
    default of the method (texture loss, content and smoothness terms, colour transfer): at Keep Scene 1 the result's
    dark half stays 0.2 / 0.8 as bright as its light half, within 0.05 (the closing colour transfer would squeeze
    the two tones together); at Keep Scene 0 the halves come out alike."""
    from gt2gs_blender.core.api import transfer

    scene, cam, _ = half_dark_wall()
    grey = np.full((64, 64, 3), 0.5, np.float32)
    config = wall_config(
        shared,
        tmp_path,
        stylise_steps=12,
        correct_steps=4,
        keep_scene=keep,
        scene_colour=0.0,
        scene_brightness=0.0,
        background=(0, 0, 0),
    )
    result = transfer(scene, grey, [cam], config)
    shown = render(result.scene, [cam], background=torch.zeros(3)).colors[0].mean(-1)
    left, right = shown[16:80, 8 : 48 - 8].mean(), shown[16:80, 48 + 8 : 96 - 8].mean()
    ratio = float(left / right)
    assert ratio == pytest.approx(0.25, abs=0.05) if keep else ratio == pytest.approx(1.0, abs=0.1)


def test_shade_softness_blurs_the_scene_s_light_and_shade_over_a_world_width(shared, tmp_path):
    """The half-dark wall with Scene Softness 0.1 repeat (0.1 world units here): four widths from the seam
    each half keeps its shade, on the seam the splats and the layout term's image take the shade of the mean
    luminance 0.5; the preview still shows exactly the zero-step run."""
    from gt2gs_blender.core.api import transfer
    from gt2gs_blender.core.transfer.layout import shade_width
    from gt2gs_blender.core.transfer.orientation_preview import preview

    scene, cam, white = half_dark_wall()
    config = zero_step_config(
        shared, tmp_path, keep_scene=1.0, scene_colour=0.0, scene_brightness=0.0, shade_softness=0.1
    )
    result = transfer(scene, white, [cam], config)
    colours, x = result.scene.base_colors.mean(1), result.scene.means[:, 0]
    dark, seam = 0.2 / 0.8, 0.5 / 0.8
    assert float(colours[x < -0.4].mean()) == pytest.approx(dark, abs=0.02)
    assert float(colours[x > 0.4].mean()) == pytest.approx(1.0, abs=0.02)
    assert float(colours[x.abs() < 0.02].mean()) == pytest.approx(seam, abs=0.03)
    one_width = (0.2 + 0.6 * 0.1587) / 0.8  # a Gaussian's tail beyond one sigma: 15.87 %
    assert float(colours[(x + 0.1).abs() < 0.02].mean()) == pytest.approx(one_width, abs=0.03)
    expected = render(result.scene, [cam], background=torch.zeros(3)).colors[0].clamp(0, 1).numpy() * 255.0
    assert np.abs(preview(scene, white, [cam], config, size=96).image.astype(np.float32) - expected).max() <= 1.0
    views = render_views(scene, [cam], torch.zeros(3), "auto")
    frame = layout_frame(scene, views, config)
    (ideal,) = layout_images(views, white, frame, 0.0, True, shade_width(frame, config))
    column = cam.fx * (x / (result.scene.means[:, 2])) + cam.cx  # where each splat's x lands on screen
    middle = round(float(column[x.abs() < 0.01].mean()))
    row = ideal[48, :, 0]
    assert float(row[middle - 1 : middle + 1].mean()) == pytest.approx(seam, abs=0.04)
    assert float(row[int(cam.cx - 0.4 * cam.fx / 3.0) - 3]) == pytest.approx(dark, abs=0.03)
    assert float(row[round(cam.cx - 0.1 * cam.fx / 3.0)]) == pytest.approx(one_width, abs=0.04)


PINK, BLUE = (0.9, 0.5, 0.5), (0.4, 0.6, 0.9)
"""Two hues of nearly one luminance (0.585 and 0.579): a donut's icing and dough to the luminance alone."""


@pytest.mark.parametrize(("grey", "left", "right"), [(1.0, 0.2, 0.8), (0.25, (5**0.5 - 1) ** 2 / 4, (5**0.5 - 1) / 2)])
def test_scene_brightness_gives_the_laid_texture_the_scene_s_mean_luminance(shared, tmp_path, grey, left, right):
    """The half-dark wall (luminance 0.2 and 0.8, mean 0.5) at Keep Scene 1, Scene Brightness 1, under a flat
    texture: white, shaded to 0.25 and 1 (mean 0.625), comes back by a gain of 0.8 to the scene itself, 0.2 and
    0.8; a dark grey 0.25, shaded to 1/16 and 1/4, by the power p with (1/16)^p + (1/4)^p = 1, so 1/4^p is
    the golden ratio's 0.618 and 1/16^p its square (nothing clips, the halves keep their order). The preview
    and the layout term's image show the same."""
    from gt2gs_blender.core.api import transfer
    from gt2gs_blender.core.transfer.orientation_preview import preview
    from gt2gs_blender.core.transfer.shade import laid_exposure, layout_shade

    scene, cam, _ = half_dark_wall()
    texture = np.full((64, 64, 3), grey, np.float32)
    config = zero_step_config(shared, tmp_path, keep_scene=1.0, scene_colour=0.0, scene_brightness=1.0)
    result = transfer(scene, texture, [cam], config)
    colours, x = result.scene.base_colors.mean(1), result.scene.means[:, 0]
    assert float(colours[x < -0.1].mean()) == pytest.approx(left, abs=0.01)
    assert float(colours[x > 0.1].mean()) == pytest.approx(right, abs=0.01)
    expected = render(result.scene, [cam], background=torch.zeros(3)).colors[0].clamp(0, 1).numpy() * 255.0
    assert np.abs(preview(scene, texture, [cam], config, size=96).image.astype(np.float32) - expected).max() <= 1.0
    views = render_views(scene, [cam], torch.zeros(3), "auto")
    exposure = laid_exposure(layout_shade(scene, None, keep=1.0, texture=texture, brightness=1.0), None)
    (ideal,) = layout_images(views, texture, layout_frame(scene, views, config), 0.0, True, exposure=exposure)
    covered = ideal[:, : 96 // 2 - 6, 3] > 0  # the wall's left half on screen, away from the seam
    assert float(ideal[:, : 96 // 2 - 6, 0][covered].mean()) == pytest.approx(left, abs=0.02)


def test_scene_brightness_below_one_takes_that_share_of_the_exposure_s_stops():
    """Scene Brightness 0.5 exposes by the square root of what 1 does (half the stops), 0 not at all."""
    from gt2gs_blender.core.transfer.shade import layout_shade

    scene, _, _ = half_dark_wall()
    texture = np.full((8, 8, 3), 0.25, np.float32)
    full, half, none = (layout_shade(scene, None, texture=texture, brightness=b)[:, 4] for b in (1.0, 0.5, 0.0))
    assert float(full[0]) > 1.5 and torch.allclose(half, full.sqrt()) and bool((none == 1.0).all())


def two_material_wall() -> tuple[GaussianScene, Camera]:
    """The wall of dark material (0.1) on its left half and light (0.6) on its right, both under one light that
    falls evenly from 1 at the top to 0.5 at the bottom (its median 0.75), and its front camera."""
    base, cam = wall(n=80), front_camera(96)
    light = 0.75 - 0.25 * base.means[:, 1]  # y = -1 is the top on screen
    albedo = torch.where(base.means[:, 0] < 0, 0.1, 0.6)
    return with_colours(base, (albedo * light)[:, None].expand(-1, 3)), cam


@pytest.mark.parametrize("brightness", [1.0, 0.0])
def test_keep_material_zero_gives_each_part_the_texture_s_brightness_and_keeps_the_light(shared, tmp_path, brightness):
    """A white texture on the two-material wall at Keep Scene 1, Scene Colour 0: with Keep Material 0 both halves
    come out alike, each splat its light over its part's median (1 down the upper half, falling to 0.5 / 0.75 at
    the bottom), whatever Scene Brightness says; with Keep Material 1 (and Scene Brightness 0) the dark half stays
    1/6 as bright as the light one. The preview shows the zero-step run, and the layout term's image (the shade per
    pixel against the material it shows) agrees."""
    from gt2gs_blender.core.api import transfer
    from gt2gs_blender.core.transfer.layout import bright_images, layout_bright
    from gt2gs_blender.core.transfer.orientation_preview import preview

    scene, cam = two_material_wall()
    white = np.ones((64, 64, 3), np.float32)
    settings = dict(keep_scene=1.0, scene_colour=0.0, scene_brightness=brightness)
    config = zero_step_config(shared, tmp_path, keep_material=0.0, **settings)
    result = transfer(scene, white, [cam], config)
    colours, x, y = result.scene.base_colors.mean(1), result.scene.means[:, 0], result.scene.means[:, 1]
    expected = ((0.75 - 0.25 * y) / 0.75).clamp(max=1.0)
    assert float((colours - expected).abs().max()) < 0.02
    assert float(colours[x < 0].mean()) == pytest.approx(float(colours[x > 0].mean()), abs=0.01)
    shown = render(result.scene, [cam], background=torch.zeros(3)).colors[0].clamp(0, 1).numpy() * 255.0
    assert np.abs(preview(scene, white, [cam], config, size=96).image.astype(np.float32) - shown).max() <= 1.0
    views = render_views(scene, [cam], torch.zeros(3), "auto")
    lit = bright_images(scene, views, layout_bright(scene, None, config), "auto")
    (ideal,) = layout_images(views, white, layout_frame(scene, views, config), 0.0, True, bright=lit)
    top, bottom = ideal[22:30, 22:74, 0], ideal[66:74, 22:74, 0]  # the wall spans rows and columns 19-77
    assert float(top.mean()) == pytest.approx(1.0, abs=0.02)
    assert float(bottom.mean()) == pytest.approx(float(expected[(y > 0.6) & (y < 0.9)].mean()), abs=0.03)
    today = zero_step_config(
        shared, tmp_path, keep_material=1.0, keep_scene=1.0, scene_colour=0.0, scene_brightness=0.0
    )
    kept = transfer(scene, white, [cam], today).scene
    grey, x = kept.base_colors.mean(1), kept.means[:, 0]
    ratio = grey[x < -0.05].mean() / grey[x > 0.05].mean()  # away from the seam, where children cross it
    assert float(ratio) == pytest.approx(1 / 6, abs=0.01)


@pytest.mark.parametrize(("keep_material", "keep_hues"), [(0.0, 0.5), (0.0, 0.0), (1.0, 0.5), (1.0, 0.0)])
def test_layout_materials_finds_the_parts_once_and_gives_what_each_alone_gives(monkeypatch, keep_material, keep_hues):
    """The two-material wall: the shade's bright ends and the parts' colours taken together equal each taken alone,
    and the parts search (the slow step on a capture) runs once when either is wanted, not at all when neither."""
    from gt2gs_blender.core.scene import parts as parts_module
    from gt2gs_blender.core.transfer import layout

    scene, _ = two_material_wall()
    config = TransferConfig(layout=True, keep_material=keep_material, keep_hues=keep_hues)
    bright_alone, parts_alone = layout.layout_bright(scene, None, config), layout.layout_parts(scene, config)
    calls = []
    monkeypatch.setattr(layout, "find_parts", lambda s: calls.append(s) or parts_module.find_parts(s))
    bright, parts = layout.layout_materials(scene, None, config)
    assert len(calls) == int(keep_material < 1.0 or keep_hues > 0.0)
    for together, alone in ((bright, bright_alone), (parts, parts_alone)):
        assert (together is None) == (alone is None)
        if alone is not None:
            assert torch.equal(together, alone)
    assert (bright is None) == (keep_material >= 1.0) and (parts is None) == (keep_hues <= 0.0)


def test_material_bright_is_each_part_s_median_against_the_scene_s_bright_end():
    """Two parts, luminance 0.1-0.3 and 0.5-0.9: Keep Material 1 takes the scene's bright end (its 95th
    percentile) everywhere, 0 each part's median, 0.5 their geometric mean; a part of one splat is its own."""
    from gt2gs_blender.core.transfer.shade import bright_end, material_bright

    luminance = torch.tensor([0.1, 0.2, 0.3, 0.5, 0.7, 0.9, 0.05])
    labels = torch.tensor([3, 3, 3, 1, 1, 1, 7])
    overall = bright_end(luminance)
    assert overall == pytest.approx(0.9)
    medians = torch.tensor([0.2, 0.2, 0.2, 0.7, 0.7, 0.7, 0.05])
    assert torch.allclose(material_bright(luminance, labels, 1.0), torch.full((7,), overall))
    assert torch.allclose(material_bright(luminance, labels, 0.0), medians)
    assert torch.allclose(material_bright(luminance, labels, 0.5), (medians * overall).sqrt())
    black = material_bright(torch.zeros(3), torch.zeros(3, dtype=torch.long), 0.0)
    assert bool(torch.isfinite(black).all()) and float(black.min()) > 0


def test_exposure_keeps_colours_in_range_and_in_order_and_is_continuous_at_one():
    """``exposed``: a gain below 1, the luminance to the power 1/e above, so 0..1 stays 0..1 at every exposure in
    range, each colour grows with the exposure, and the two sides meet at 1 (the colours as they are); lighter
    keeps an orange's hue and saturation, and nears white only once its red channel reaches 1."""
    from gt2gs_blender.core.transfer.shade import EXPOSURE_RANGE, exposed

    colours = torch.linspace(0.0, 1.0, 101)[:, None].expand(101, 3)
    exposures = torch.exp(torch.linspace(math.log(EXPOSURE_RANGE[0]), math.log(EXPOSURE_RANGE[1]), 41))
    out = torch.stack([exposed(colours, float(e)) for e in exposures])
    assert bool(((out >= 0) & (out <= 1)).all()) and bool((out.diff(dim=0) >= 0).all())
    assert bool((out.diff(dim=1) >= 0).all())  # the texture's light and dark keep their order
    assert torch.equal(exposed(colours, 1.0), colours)
    assert torch.allclose(exposed(colours, 1.0 - 1e-6), exposed(colours, 1.0 + 1e-6), atol=1e-5)
    # lighter keeps the hue and saturation (the channels' ratios) until a channel reaches 1, then nears white
    orange = torch.tensor([[0.4, 0.2, 0.05]])
    lighter = exposed(orange, 1.5)
    luma = torch.tensor([0.2126, 0.7152, 0.0722])
    assert torch.allclose(lighter / lighter.max(), orange / orange.max(), atol=1e-6)
    assert float(lighter @ luma) == pytest.approx(float(orange @ luma) ** (1 / 1.5), rel=1e-5)
    whiter = exposed(orange, 5.0)
    assert float(whiter.max()) == pytest.approx(1.0) and float(whiter @ luma) == pytest.approx(
        float(orange @ luma) ** 0.2, rel=1e-5
    )


def test_brightness_exposure_meets_the_target_or_stops_at_its_range():
    """Against an analytic mean: a flat 0.4 texture under a flat shade 0.5 (mix 0.2) and a scene of luminance
    0.6 is exposed by the power log 0.6 / log 0.2; a black texture and no scene colour cannot brighten, so the
    exposure stops at the range's top and the result stays black (finite); a black scene stops it at the range's
    bottom; no weight: 1."""
    from gt2gs_blender.core.transfer.shade import EXPOSURE_RANGE, brightness_exposure, exposed, kept_scene

    n = 500
    kept = kept_scene(torch.full((n,), 0.5), torch.zeros(n, 3), 0.0)
    luminance, weights = torch.full((n,), 0.6), torch.ones(n)
    e = brightness_exposure(np.full((16, 16, 3), 0.4, np.float32), kept, luminance, weights)
    assert 1.0 / e == pytest.approx(math.log(0.6) / math.log(0.2), rel=1e-4)
    assert exposed(torch.full((1, 3), 0.2), e) == pytest.approx(torch.full((1, 3), 0.6), abs=1e-4)
    black = brightness_exposure(np.zeros((16, 16, 3), np.float32), kept, luminance, weights)
    assert black == pytest.approx(EXPOSURE_RANGE[1], rel=1e-6) and float(exposed(torch.zeros(1, 3), black).max()) == 0
    dark = brightness_exposure(np.ones((4, 4, 3), np.float32), kept, torch.zeros(n), weights)  # a black scene
    assert dark == pytest.approx(EXPOSURE_RANGE[0], rel=1e-6)
    assert brightness_exposure(np.ones((4, 4, 3), np.float32), kept, luminance, torch.zeros(n)) == 1.0


def two_hue_wall() -> tuple[GaussianScene, Camera]:
    """The wall pink on its left half and blue on its right, its front camera."""
    base, cam = wall(n=80), front_camera(96)
    left = base.means[:, 0] < 0
    colours = torch.where(left[:, None], torch.tensor(PINK).expand(len(base), 3), torch.tensor(BLUE))
    return with_colours(base, colours), cam


@pytest.mark.parametrize("colour", [0.3, 1.0, 0.0])
def test_scene_colour_mixes_each_part_s_own_colour_under_the_texture(shared, tmp_path, colour):
    """A mid-grey texture on the two-hue wall at Keep Scene 1 and Scene Colour ``colour``: each half comes out
    exactly (1 - colour) x grey x its shade (its luminance over the brighter half's) + colour x its own colour
    (Scene Brightness 0: the mix as it is),
    on the splats, in the preview and in the layout term's image (0: both halves grey, as the luminance keeps
    them alike; 1: the scene's colours back, no texture)."""
    from gt2gs_blender.core.api import transfer
    from gt2gs_blender.core.transfer.orientation_preview import preview

    scene, cam = two_hue_wall()
    grey = np.full((64, 64, 3), 0.5, np.float32)
    config = zero_step_config(
        shared, tmp_path, keep_scene=1.0, scene_colour=colour, scene_brightness=0.0, shade_softness=0.0, keep_hues=0.0
    )
    result = transfer(scene, grey, [cam], config)
    luma = np.array([0.2126, 0.7152, 0.0722])
    bright = max(float(np.dot(PINK, luma)), float(np.dot(BLUE, luma)))
    for hue, side in ((PINK, result.scene.means[:, 0] < -0.1), (BLUE, result.scene.means[:, 0] > 0.1)):
        expected = (1.0 - colour) * 0.5 * float(np.dot(hue, luma)) / bright + colour * np.array(hue)
        assert result.scene.base_colors[side].mean(0).numpy() == pytest.approx(expected, abs=0.01)
    expected_image = render(result.scene, [cam], background=torch.zeros(3)).colors[0].clamp(0, 1).numpy() * 255.0
    assert np.abs(preview(scene, grey, [cam], config, size=96).image.astype(np.float32) - expected_image).max() <= 1.0
    views = render_views(scene, [cam], torch.zeros(3), "auto")
    (ideal,) = layout_images(views, grey, layout_frame(scene, views, config), 0.0, True, keep=1.0, colour=colour)
    left = (1.0 - colour) * 0.5 * float(np.dot(PINK, luma)) / bright + colour * np.array(PINK)
    covered = ideal[:, : 96 // 2 - 6, 3] > 0  # the wall's left half on screen, away from the seam
    assert ideal[:, : 96 // 2 - 6, :3][covered].mean(0).numpy() == pytest.approx(left, abs=0.02)


@pytest.mark.parametrize("colour, hues", [(0.3, 0.0), (0.0, 0.0), (0.0, None)])
def test_a_whole_run_keeps_parts_that_differ_only_in_hue_apart(shared, tmp_path, colour, hues):
    """The two-hue wall under a flat grey texture, a whole short run with every default of the method: at Scene
    Colour 0.3 the halves stay apart along their colours' difference by half to all of Scene Colour's share
    (the start holds all of it, 12 steps of the grey texture's pull keep about two thirds); at 0, with Keep Hues
    0, they come out alike (Keep Scene keeps luminance, and theirs is nearly one), and with Keep Hues at its
    default (None) they stay apart by half to all of the hue shift the start holds (worked out by hand)."""
    from gt2gs_blender.core.api import transfer

    scene, cam = two_hue_wall()
    grey = np.full((64, 64, 3), 0.5, np.float32)
    config = wall_config(
        shared,
        tmp_path,
        stylise_steps=12,
        correct_steps=4,
        scene_colour=colour,
        scene_brightness=0.0,
        background=(0, 0, 0),
        **({} if hues is None else {"keep_hues": hues}),
    )
    shown = render(transfer(scene, grey, [cam], config).scene, [cam], background=torch.zeros(3)).colors[0]
    difference = (shown[16:80, 8 : 48 - 8].mean((0, 1)) - shown[16:80, 48 + 8 : 96 - 8].mean((0, 1))).numpy()
    if hues is None:  # each half starts as the grey 0.5 shaded, its hue moved by Keep Hues of its own, by hand
        luma, keep = np.array([0.2126, 0.7152, 0.0722]), TransferConfig().keep_hues
        bright = max(float(np.dot(PINK, luma)), float(np.dot(BLUE, luma)))
        start = [
            float(np.dot(c, luma)) / bright * 0.5 * (1.0 + keep * (np.array(c) / np.dot(c, luma) - 1.0))
            for c in (PINK, BLUE)
        ]
        apart = start[0] - start[1]
    elif colour == 0.0:
        assert np.abs(difference).max() < 0.05
        return
    else:
        apart = colour * (np.array(PINK) - np.array(BLUE))
    share = float(difference @ apart) / float(apart @ apart)
    along = float(difference @ apart) / (np.linalg.norm(difference) * np.linalg.norm(apart))
    assert 0.5 <= share <= 1.0 and along > 0.98


def test_spatial_blur_is_a_gaussian_weighted_average_of_the_neighbours():
    """Against the float64 brute-force weighted Gaussian average over random points: close at every point;
    a constant stays that constant exactly; no blur (sigma 0) returns the values."""
    from gt2gs_blender.core.transfer.shade import spatial_blur

    g = torch.Generator().manual_seed(0)
    points, values = torch.rand(3000, 3, generator=g), torch.rand(3000, generator=g)
    weights = torch.rand(3000, generator=g) + 0.1
    for sigma in (0.05, 0.15):
        near = torch.exp(-(torch.cdist(points.double(), points.double()) ** 2) / (2 * sigma**2)) * weights.double()
        oracle = near @ values.double() / near.sum(1)
        error = (spatial_blur(points, values, weights, sigma).double() - oracle).abs()
        assert float(error.mean()) < 0.01 and float(error.max()) < 0.04, sigma
    flat = spatial_blur(points, torch.full((3000,), 0.3), weights, 0.1)
    assert torch.allclose(flat, torch.full((3000,), 0.3), atol=1e-5)
    assert torch.equal(spatial_blur(points, values, weights, 0.0), values)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
def test_spatial_blur_takes_and_returns_cuda_tensors():
    """A CUDA run's splats: the blur (on the CPU inside) returns on CUDA, equal to the CPU result."""
    from gt2gs_blender.core.transfer.shade import spatial_blur

    points, values = torch.rand(500, 3), torch.rand(500)
    out = spatial_blur(points.cuda(), values.cuda(), torch.ones(500).cuda(), 0.1)
    assert out.is_cuda and torch.allclose(out.cpu(), spatial_blur(points, values, torch.ones(500), 0.1))


def test_spatial_blur_degenerate_inputs_stay_finite_and_in_range():
    """One point, all points in one place, weights of zero, a far outlier: finite, within the values' range."""
    from gt2gs_blender.core.transfer.shade import spatial_blur

    one = spatial_blur(torch.zeros(1, 3), torch.tensor([0.7]), torch.ones(1), 0.1)
    assert torch.allclose(one, torch.tensor([0.7]))
    same = spatial_blur(torch.ones(50, 3), torch.linspace(0, 1, 50), torch.ones(50), 0.1)
    assert torch.allclose(same, torch.full((50,), 0.5), atol=1e-5)  # one place: the plain mean
    values = torch.rand(200, generator=torch.Generator().manual_seed(1))
    points = torch.rand(200, 3, generator=torch.Generator().manual_seed(2))
    points[0] = 1e4  # a floater far outside the grid reads its border
    for weights in (torch.zeros(200), torch.ones(200)):
        out = spatial_blur(points, values, weights, 0.05)
        assert torch.isfinite(out).all()
        assert float(out.min()) >= float(values.min()) - 1e-5 and float(out.max()) <= float(values.max()) + 1e-5


def test_layout_images_show_the_bars_at_the_repeat_and_the_loss_ignores_uncovered_pixels():
    """The ideal per-view image of the layout has the bars' period on screen; the layout loss is 0 on
    it whatever lies off the surface, and grows with a change on the surface."""
    from gt2gs_blender.core.transfer.losses import layout_loss

    scene, cam = wall(n=100), front_camera(96)
    views = render_views(scene, [cam], torch.ones(3), "auto")
    frame = layout_frame(scene, views, TransferConfig(texture_repeats=2.0))
    (ideal,) = layout_images(views, stripes(period=32, size=128), frame, 0.0)
    assert ideal.shape == (96, 96, 4)
    row = ideal[48, 20:-20, :3].mean(-1).numpy()
    spectrum = np.abs(np.fft.rfft(row - row.mean()))
    period_px = len(row) / int(np.argmax(spectrum))
    expected_px = frame.repeat / 4 * cam.fx / 3.0  # a quarter of the repeat, 3 units away
    assert period_px == pytest.approx(expected_px, rel=0.15)
    covered = views.alphas[0] >= 0.9
    assert torch.equal(ideal[..., 3] > 0, covered)
    off = torch.where(covered[..., None], ideal[..., :3], torch.rand(96, 96, 3))
    scene_colours = torch.rand(96, 96, 3)
    assert float(layout_loss(off, ideal, scene_colours)) == 0.0
    assert float(layout_loss(ideal[..., :3] + 0.1, ideal, ideal[..., :3])) == pytest.approx(0.1, rel=1e-4)
    black = ideal.clone()
    black[..., :3] = 0.0  # a black texture still counts on the surface
    assert float(layout_loss(torch.full((96, 96, 3), 0.5), black, black[..., :3])) == pytest.approx(0.5, rel=1e-6)


@pytest.mark.parametrize("split_first", [True, False])
def test_a_region_transfer_with_the_layout_leaves_the_rest_bit_identical(shared, tmp_path, split_first):
    """Only the region is laid out and split (before or after refining); the Gaussians outside it come out
    first, unchanged."""
    from gt2gs_blender.core.api import transfer

    scene, cam = wall(n=60), front_camera(96)
    region = scene.means[:, 0] < 0
    config = wall_config(
        shared, tmp_path, stylise_steps=4, correct_steps=2, n_angles=4, split_size=0.01, split_first=split_first
    )
    result = transfer(scene, stripes(), [cam], config, region=region)
    outside = int((~region).sum())
    for name, value in scene.subset(~region).tensors().items():
        assert torch.equal(result.scene.tensors()[name][:outside], value), name
    restyled = result.scene.subset(torch.arange(outside, len(result.scene)))
    assert len(restyled) > int(region.sum())  # split for detail
    assert float(restyled.means[:, 0].max()) < 0.05  # and only inside the region


def test_each_point_reads_the_texture_blurred_to_its_own_footprint():
    """A point with a footprint far above the bars' period reads their mean; a tiny one reads a bar."""
    from gt2gs_blender.core.transfer.layout import LayoutFrame, project_texture

    frame = LayoutFrame(axes=np.eye(3), repeat=1.0)  # one texture height per world unit
    texture = stripes(period=16, size=128)  # bars 8 texture px = 1/16 unit wide
    x = torch.full((2,), 0.25 / 8 + 0.001)  # the middle of the first white bar
    points = torch.stack([x, torch.zeros(2), torch.zeros(2)], -1)
    normals = torch.tensor([[0.0, 0.0, 1.0]]).expand(2, 3)
    fine, coarse = project_texture(points, normals, texture, frame, 0.0, torch.tensor([1e-4, 0.5])).mean(-1)
    assert float(fine) > 0.95 or float(fine) < 0.05
    assert abs(float(coarse) - 0.5) < 0.05


@pytest.mark.parametrize("footprint", [0.02, 0.2, 0.6])  # pyramid levels 0, 4 and 5: no blur, 8 px and 16 px
def test_the_layout_reads_the_texture_without_a_seam(footprint):
    """The sampler and the prefilter pyramid read the texture as it tiles: a photo rolled by half its size, read
    half a repeat further on, gives every point the same colour, at the repeat's edges too (a mirrored blur, and a
    sampler clamped at the photo's border, did not)."""
    from gt2gs_blender.core.transfer.layout import LayoutFrame, project_texture

    frame = LayoutFrame(axes=np.eye(3), repeat=1.0)
    y, x = np.mgrid[0:64, 0:64].astype(np.float32)
    texture = np.stack([x / 63, y / 63, (x * y) % 7 / 6], axis=-1)  # ramps that jump at the edges
    points = torch.stack([torch.linspace(-0.1, 1.1, 97), torch.linspace(0.05, 0.95, 97), torch.zeros(97)], -1)
    normals = torch.tensor([[0.0, 0.0, 1.0]]).expand(97, 3)
    shifted = points + torch.tensor([0.5, -0.5, 0.0])  # texture x right, y down: the world's +up reads -y
    rolled = np.roll(texture, (32, 32), axis=(0, 1))
    here = project_texture(points, normals, texture, frame, 0.0, footprint)
    there = project_texture(shifted, normals, rolled, frame, 0.0, footprint)
    torch.testing.assert_close(there, here, atol=2e-4, rtol=0.0)


def test_splitting_first_lays_out_the_same_start(shared, tmp_path):
    """Split Before Refining changes when the coarse splats split, not what is laid: with no steps the run
    equals the one that splits at the end, splat for splat, shade included."""
    from gt2gs_blender.core.api import transfer

    scene, cam, _ = half_dark_wall()
    texture = stripes(period=16, size=64)
    at_end = transfer(scene, texture, [cam], zero_step_config(shared, tmp_path, split_first=False)).scene
    first = transfer(scene, texture, [cam], zero_step_config(shared, tmp_path, split_first=True)).scene
    assert len(first) == len(at_end) > 2 * len(scene)
    assert torch.equal(first.means, at_end.means)
    assert torch.allclose(first.sh_dc, at_end.sh_dc, atol=1e-5)


@pytest.mark.parametrize("split_first", [True, False])
def test_the_split_budget_bounds_the_saved_splats(shared, tmp_path, split_first):
    """Split Budget caps what the detail split adds, whichever order it runs in: 1 leaves the wall's count,
    2 at most doubles it, and the default (12) makes more than 2 would."""
    from gt2gs_blender.core.api import transfer

    scene, cam, _ = half_dark_wall()
    texture = stripes(period=16, size=64)
    counts = {
        budget: len(
            transfer(
                scene, texture, [cam], zero_step_config(shared, tmp_path, split_budget=budget, split_first=split_first)
            ).scene
        )
        for budget in (1.0, 2.0, 12.0)
    }
    assert counts[1.0] == len(scene)
    assert len(scene) < counts[2.0] <= 2 * len(scene) < counts[12.0] <= 12 * len(scene)
    with pytest.raises(ValueError, match="split_budget"):
        TransferConfig(split_budget=0.5)


def test_layout_loss_charges_a_hue_more_than_the_same_step_in_light_and_dark():
    """Over a grey texture on a grey scene: a grey step of d costs d, as a per-channel L1 charged it; a step
    of d in green alone costs 0.7152 d in luma and 4 x 2 x 0.7152 d in the colour differences, so the
    texture term draws its dark lines dark instead of buying them with one channel (the magenta dots at
    woven straw's crossings)."""
    from gt2gs_blender.core.transfer.losses import HUE_WEIGHT, layout_loss
    from gt2gs_blender.core.transfer.tone import LUMA

    ideal = torch.cat([torch.full((8, 8, 3), 0.5), torch.ones(8, 8, 1)], -1)
    darker = ideal[..., :3] - 0.2
    green_only = ideal[..., :3] - torch.tensor([0.0, 0.2, 0.0])
    assert float(layout_loss(darker, ideal, ideal[..., :3])) == pytest.approx(0.2, rel=1e-5)
    expected = LUMA[1] * 0.2 * (1 + 2 * HUE_WEIGHT)
    assert float(layout_loss(green_only, ideal, ideal[..., :3])) == pytest.approx(expected, rel=1e-5)


def test_layout_loss_lets_a_hue_drift_back_to_the_scenes_own_for_free():
    """A grey texture over a red scene: a result part of the way to the scene's hue, or at it, at the
    texture's luma, costs nothing; one past it, or the same colour step toward blue, costs HUE_WEIGHT x the L1
    distance of its colour differences (R - Y, B - Y) from the path's nearest point, worked out by hand."""
    from gt2gs_blender.core.transfer.losses import HUE_WEIGHT, layout_loss
    from gt2gs_blender.core.transfer.tone import LUMA

    ideal = torch.cat([torch.full((4, 4, 3), 0.5), torch.ones(4, 4, 1)], -1)
    luma = np.array(LUMA)

    def at_luma(rgb: list[float]) -> torch.Tensor:
        """The colour shifted in grey to the texture's luma 0.5, filling the image."""
        colour = np.array(rgb) + 0.5 - np.array(rgb) @ luma
        return torch.tensor(colour, dtype=torch.float32).expand(4, 4, 3)

    red = at_luma([0.9, 0.5, 0.5])
    path = 0.4 * np.array([1 - LUMA[0], -LUMA[0]])  # grey -> red in (R - Y, B - Y)
    assert float(layout_loss(red, ideal, red)) == pytest.approx(0.0, abs=1e-6)
    assert float(layout_loss(at_luma([0.7, 0.5, 0.5]), ideal, red)) == pytest.approx(0.0, abs=1e-6)
    past = HUE_WEIGHT * np.abs(0.25 * path).sum()  # a quarter of the path again beyond the scene's hue
    assert float(layout_loss(at_luma([1.0, 0.5, 0.5]), ideal, red)) == pytest.approx(past, rel=1e-4)
    toward_blue = 0.4 * np.array([-LUMA[2], 1 - LUMA[2]])
    nearest = np.clip(toward_blue @ path / (path @ path), 0.0, 1.0) * path
    off = HUE_WEIGHT * np.abs(toward_blue - nearest).sum()
    assert off > 0.4 and float(layout_loss(at_luma([0.5, 0.5, 0.9]), ideal, red)) == pytest.approx(off, rel=1e-4)


def test_layout_loss_stays_finite_where_the_texture_and_the_scene_share_a_hue():
    """Stress: the path of length zero (texture = scene), of a length under float32's smallest normal, and
    a result exactly on the path: the loss and its gradient are finite, and a zero path costs the plain
    distance from the texture's hue."""
    from gt2gs_blender.core.transfer.losses import HUE_WEIGHT, layout_loss
    from gt2gs_blender.core.transfer.tone import LUMA

    g = torch.Generator().manual_seed(3)
    texture = torch.rand(16, 16, 3, generator=g)
    ideal = torch.cat([texture, torch.ones(16, 16, 1)], -1)
    black = torch.cat([torch.zeros(16, 16, 3), torch.ones(16, 16, 1)], -1)
    subnormal = torch.tensor([1e-39, 0.0, 0.0])  # a path whose squared length underflows to 0
    assert float((subnormal * subnormal).sum()) == 0.0 and float(subnormal[0]) > 0.0
    cases = [(ideal, texture), (ideal, texture * (1 + 1e-7)), (black, black[..., :3] + subnormal)]
    for layout, scene in cases:
        for start in (layout[..., :3], scene, torch.rand(16, 16, 3, generator=g)):
            result = start.clone().requires_grad_(True)
            loss = layout_loss(result, layout, scene)
            loss.backward()
            assert torch.isfinite(loss) and torch.isfinite(result.grad).all()
    red_step = texture + torch.tensor([0.1, 0.0, 0.0])
    luma_part = 0.1 * LUMA[0]
    chroma_part = 0.1 * (1 - LUMA[0]) + 0.1 * LUMA[0]
    assert float(layout_loss(red_step, ideal, texture)) == pytest.approx(luma_part + HUE_WEIGHT * chroma_part, rel=1e-4)
