"""The run's working resolution (``working_resolution``): larger for a dense capture, against a card's area worked out
by hand, and the plan's views at it."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from gt2gs_blender.core.cameras.camera import Camera
from gt2gs_blender.core.render import render
from gt2gs_blender.core.scene.gaussians import GaussianScene
from gt2gs_blender.core.transfer.config import SPLATS_PER_PIXEL, TransferConfig
from gt2gs_blender.core.transfer.metrics import COVERED, MEASURE_SIDE, MEASURE_STRIDE, content_metrics
from gt2gs_blender.core.transfer.orientation_preview import preview
from gt2gs_blender.core.transfer.pipeline import transfer
from gt2gs_blender.core.transfer.plan import plan_run
from gt2gs_blender.core.transfer.resolution import RESOLUTION_STEP, object_pixels, working_resolution

SIDE = 128
"""The card's camera: a square view SIDE px wide with a 90 degree field of view, looking along +z."""
DISTANCE = 2.0
HALF_WIDTH = 1.0
CARD_PIXELS = (HALF_WIDTH / DISTANCE * SIDE) ** 2
"""The card x, y in [-1, 1] at z = 2 spans half the width of the image (f = SIDE / 2): 64 x 64 px."""


def card(per_side: int) -> GaussianScene:
    """A square card of ``per_side`` x ``per_side`` opaque splats facing the camera, each as wide as its spacing."""
    spacing = 2 * HALF_WIDTH / per_side
    centres = torch.linspace(-HALF_WIDTH + spacing / 2, HALF_WIDTH - spacing / 2, per_side, dtype=torch.float32)
    x, y = torch.meshgrid(centres, centres, indexing="ij")
    means = torch.stack([x.flatten(), y.flatten(), torch.full((per_side**2,), DISTANCE)], dim=1)
    n = len(means)
    scales = torch.tensor([spacing / 2, spacing / 2, spacing / 20]).expand(n, 3).clone()
    return GaussianScene.from_activated(means, scales, torch.full((n,), 0.99), torch.full((n, 3), 0.5))


def camera() -> list[Camera]:
    return [Camera(np.eye(4), SIDE / 2, SIDE / 2, SIDE / 2, SIDE / 2, SIDE, SIDE)]


def expected(n: int, config: TransferConfig) -> int:
    """The resolution worked out by hand: the card's pixels grow with the square of the side."""
    density = n / CARD_PIXELS * (SIDE / config.resolution) ** 2
    if density <= SPLATS_PER_PIXEL:
        return config.resolution
    side = config.resolution * math.sqrt(density / SPLATS_PER_PIXEL)
    return min(int(config.resolution * config.dense_upscale), RESOLUTION_STEP * math.ceil(side / RESOLUTION_STEP))


def test_the_card_covers_the_pixels_worked_out_by_hand() -> None:
    """The object's pixels, measured on small renders and scaled to the views' size, are the card's area (within
    the one-pixel rim the splats' footprints add around it)."""
    config = TransferConfig(resolution=SIDE)
    assert object_pixels(card(60), camera(), config, "+z") == pytest.approx(CARD_PIXELS, rel=0.07)


@pytest.mark.parametrize("per_side", [300, 200])
def test_a_dense_card_is_worked_at_the_size_that_puts_at_most_four_splats_behind_a_pixel(per_side: int) -> None:
    """90,000 splats on 4,096 px (22 a pixel) are worked at 304 px, 40,000 (10 a pixel) at 208: no more than
    SPLATS_PER_PIXEL splats behind a pixel of the card."""
    config = TransferConfig(resolution=SIDE, dense_upscale=8.0)
    got = working_resolution(card(per_side), camera(), config, "+z")
    assert abs(got - expected(per_side**2, config)) <= RESOLUTION_STEP
    assert got > SIDE
    assert per_side**2 / (CARD_PIXELS * (got / SIDE) ** 2) <= SPLATS_PER_PIXEL * 1.1


def test_a_sparse_card_keeps_the_resolution_asked_for() -> None:
    """400 splats on 4,096 px: the run works at the resolution asked for."""
    assert working_resolution(card(20), camera(), TransferConfig(resolution=SIDE), "+z") == SIDE


@pytest.mark.parametrize(("upscale", "want"), [(2.0, 256), (1.5, 192), (1.0, SIDE)])
def test_the_larger_size_stops_at_dense_upscale_times_the_resolution(upscale: float, want: int) -> None:
    """A dense card wants 304 px: Dense Upscale caps it at that many times Resolution, and 1 (TransferConfig's
    default, what ``preview`` keeps) never grows."""
    config = TransferConfig(resolution=SIDE, dense_upscale=upscale)
    assert working_resolution(card(300), camera(), config, "+z") == want


def test_the_plan_s_views_are_at_the_working_resolution_and_the_report_says_so() -> None:
    """The plan renders its views at the larger size and records it beside the resolution asked for."""
    config = TransferConfig(resolution=SIDE, dense_upscale=4.0, layout=False, device="cpu")
    plan = plan_run(card(300), np.full((8, 8, 3), 0.5, dtype=np.float32), camera(), config, preview=True)
    size = plan.config.resolution
    assert plan.asked.resolution == SIDE
    assert abs(size - expected(300**2, config)) <= RESOLUTION_STEP
    assert plan.resolved()["resolution"] == size
    assert [(c.width, c.height) for c in plan.cameras] == [(size, size)]


def test_scene_kept_is_measured_at_one_size_whatever_size_the_run_worked_at(tmp_path) -> None:
    """A dense card worked at 256 px and the same card asked for at 256 px are both judged at MEASURE_SIDE on every
    MEASURE_STRIDE-th view: the report's content measures are those of the result and the original rendered
    independently from those views at that size."""
    base = dict(
        stylise_steps=4,
        correct_steps=0,
        n_scales=2,
        n_angles=4,
        texture_height=64,
        gpb=False,
        densify=False,
        evaluate=True,
        device="cpu",
        cache_dir=str(tmp_path),
    )
    scene = card(300)
    stripes = np.zeros((64, 64, 3), dtype=np.float32)
    stripes[:, ::8] = 1.0
    turned = np.eye(4)
    turned[:3, :3] = np.array([[0.8, 0.0, -0.6], [0.0, 1.0, 0.0], [0.6, 0.0, 0.8]])  # 37 degrees about y
    cameras = [*camera(), Camera(turned, SIDE / 2, SIDE / 2, SIDE / 2, SIDE / 2, SIDE, SIDE)]

    def measured(result: GaussianScene, size: int) -> dict[str, float | None]:
        cams = [c.scaled(size / SIDE) for c in cameras[::MEASURE_STRIDE]]
        after = render(result, cams, background=(1.0, 1.0, 1.0), backend="auto")
        before = render(scene, cams, background=(1.0, 1.0, 1.0), backend="auto")
        return content_metrics(after.colors, before.colors, before.alphas > COVERED)

    for config in (TransferConfig(resolution=SIDE, dense_upscale=2.0, **base), TransferConfig(resolution=256, **base)):
        result = transfer(scene, stripes, cameras, config)
        assert result.report["image_size"] == [256, 256]
        reported, judged = result.report["metrics"], measured(result.scene, MEASURE_SIDE)
        for name in ("ssim", "object_ssim", "object_ssim_blurred"):
            assert reported[name] == pytest.approx(judged[name], abs=1e-4), name
        assert abs(judged["object_ssim"] - measured(result.scene, 256)["object_ssim"]) > 0.01


def test_the_preview_says_the_size_the_run_works_at() -> None:
    """The orientation preview reports the run's views: a dense card asked at 128 px is worked at 256, a sparse one
    at 128 (Blender shows it before the run)."""
    texture = np.full((8, 8, 3), 0.5, dtype=np.float32)
    config = TransferConfig(resolution=SIDE, dense_upscale=2.0, layout=False, device="cpu")
    for per_side, side in ((300, 256), (20, SIDE)):
        shown = preview(card(per_side), texture, camera(), config, size=64)
        assert (shown.views, shown.size) == (1, (side, side))
