"""Numerical stress suite: degenerate Gaussians and cameras through every CPU backend, and the optimiser guard.

Every case renders raw scene parameters (what files and optimisers hold) through ``render`` on each
available CPU backend and asserts (1) finite, in-range colours, depths and alphas, (2) finite
gradients for every raw parameter, and (3) agreement with the float64 dense reference
(tests/reference.py) on the pixels where no alpha-rule decision is within rounding distance of its
threshold. Invisible degenerate Gaussians must moreover leave the other Gaussians' render and
gradients exactly as they are without them.
"""

from __future__ import annotations

import logging
import math
from dataclasses import replace

import numpy as np
import pytest
import torch

from gt2gs_blender.core.cameras.camera import Camera
from gt2gs_blender.core.fit.trainer import FitConfig, Trainer
from gt2gs_blender.core.render import available_backends, render
from gt2gs_blender.core.scene.gaussians import GaussianScene, quats_to_rotmats
from gt2gs_blender.core.train.densify import DensifyConfig, DensityStats, densify_and_prune
from gt2gs_blender.core.train.optim import BACKOFF_AFTER, PARAM_NAMES, GaussianAdam, StepGuard

from .reference import render_reference

pytestmark = pytest.mark.stress

BACKENDS = available_backends("cpu")
WIDTH, HEIGHT, FOCAL = 40, 32, 36.0
TOL = 1e-4
NEAR = 0.01


def camera(z: float = 0.0, yaw: float = 0.0, width: int = WIDTH, height: int = HEIGHT) -> Camera:
    """A camera at (0, 0, z) looking along +z (turned by ``yaw`` about y), OpenCV axes."""
    c, s = math.cos(yaw), math.sin(yaw)
    rot_c2w = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    return Camera.from_cam_to_world(
        rot_c2w, (0.0, 0.0, z), FOCAL, FOCAL * 1.1, width / 2.0 + 0.3, height / 2.0 - 0.2, width, height
    )


def raw_scene(rows: list[dict], sh_degree: int = 0) -> GaussianScene:
    """A scene of raw parameters, one dict per Gaussian (missing keys: a small opaque red-ish blob)."""
    default = {
        "mean": (0.0, 0.0, 2.0),
        "quat": (1.0, 0.0, 0.0, 0.0),
        "log_scale": (-2.5, -2.5, -2.5),
        "logit": 1.5,
        "dc": (0.8, -0.5, 0.1),
    }
    rows = [{**default, **row} for row in rows]

    def column(key: str) -> torch.Tensor:
        return torch.tensor([row[key] for row in rows], dtype=torch.float32).reshape(len(rows), -1)

    n = len(rows)
    k = (sh_degree + 1) ** 2 - 1
    rest = torch.stack([0.3 * torch.randn(k, 3, generator=torch.Generator().manual_seed(i)) for i in range(n)])
    return GaussianScene(
        means=column("mean"),
        quats=column("quat"),
        log_scales=column("log_scale"),
        opacity_logits=column("logit").reshape(n),
        sh_dc=column("dc"),
        sh_rest=rest,
    )


def backgrounds() -> list[dict]:
    """Three ordinary Gaussians in front of the camera, beside which each degenerate one is put."""
    return [
        {"mean": (0.3, -0.2, 2.5), "dc": (0.1, 0.9, -0.3)},
        {"mean": (-0.4, 0.1, 3.0), "log_scale": (-2.0, -3.0, -2.2), "quat": (0.7, 0.1, -0.5, 0.2)},
        {"mean": (0.0, 0.3, 1.5), "logit": -0.5, "dc": (-0.6, 0.2, 0.9)},
    ]


def render_with_grads(scene: GaussianScene, cameras: list[Camera], backend: str):
    """Render raw leaf parameters and backpropagate a loss touching colour, depth and alpha."""
    leaves = scene.map_tensors(lambda t: t.detach().clone().requires_grad_(True))
    out = render(leaves, cameras, backend=backend, background=(0.2, 0.4, 0.6), sh_degree=leaves.sh_degree)
    g = torch.Generator().manual_seed(1)
    weights = [torch.rand(t.shape, generator=g) for t in (out.colors, out.depths, out.alphas)]
    loss = sum((w * t).sum() for w, t in zip(weights, (out.colors, out.depths, out.alphas)))
    loss.backward()
    grads = {name: t.grad for name, t in leaves.tensors().items()}
    return out, grads


def assert_finite(out, grads) -> None:
    for name, t in (("colors", out.colors), ("depths", out.depths), ("alphas", out.alphas)):
        assert bool(torch.isfinite(t).all()), f"non-finite {name}"
    alphas = out.alphas.detach()
    assert float(alphas.min()) >= 0.0 and float(alphas.max()) <= 1.0
    for name, g in grads.items():
        assert g is not None and bool(torch.isfinite(g).all()), f"non-finite gradient of {name}"


def assert_matches_reference(scene: GaussianScene, cameras: list[Camera], out, min_defined: float = 0.9) -> None:
    """Colour (over the background), alpha and depth against the float64 reference, per camera."""
    with torch.no_grad():
        args = [t.double().numpy() for t in (scene.means, scene.quats, scene.scales, scene.opacities)]
    degree = scene.sh_degree
    for b, cam in enumerate(cameras):
        ref = render_reference(
            *args, scene.sh.detach().double().numpy(), cam.world_to_cam, cam.K, cam.width, cam.height, sh_degree=degree
        )
        ok = ~ref.ambiguous
        assert ok.mean() >= min_defined, "too many threshold-ambiguous pixels for a meaningful comparison"
        color = ref.color + (1.0 - ref.alpha[..., None]) * np.array([0.2, 0.4, 0.6])
        assert np.abs(out.colors[b].detach().double().numpy() - color)[ok].max() <= TOL
        assert np.abs(out.alphas[b].detach().double().numpy() - ref.alpha)[ok].max() <= TOL
        depth_scale = max(1.0, float((ref.depth / np.maximum(ref.alpha, 1e-3)).max()))
        assert np.abs(out.depths[b].detach().double().numpy() - ref.depth)[ok].max() <= TOL * depth_scale


SQRT_HALF = math.sqrt(0.5)
C8, S8 = math.cos(math.pi / 8), math.sin(math.pi / 8)
NEEDLE = math.log(1e-6)
DEGENERATE = {
    # scales
    "zero-scale": {"log_scale": (-1e4, -1e4, -1e4)},
    "tiny-scale": {"log_scale": (-30.0, -30.0, -30.0)},
    "huge-scale": {"log_scale": (30.0, 30.0, 30.0), "logit": -3.0},
    "overflowing-scale": {"log_scale": (100.0, -2.0, -2.0), "logit": -4.0},
    "aniso-1e6-needle-along-view": {"log_scale": (-1.0 + NEEDLE, -1.0 + NEEDLE, -1.0)},
    "aniso-1e6-needle-in-screen-45deg": {"log_scale": (-1.0, -1.0 + NEEDLE, -1.0 + NEEDLE), "quat": (C8, 0.0, 0.0, S8)},
    "aniso-1e6-disk-edge-on": {"log_scale": (-1.5, -1.5, -1.5 + NEEDLE), "quat": (SQRT_HALF, SQRT_HALF, 0.0, 0.0)},
    "float32-cancellation-needle": {
        "log_scale": (6.3, 6.3 + NEEDLE, 6.3 + NEEDLE),
        "quat": (C8, 0.0, 0.0, S8),
        "logit": -1.0,
    },
    "aniso-1e6-disk-tilted": {"log_scale": (-1.2, -1.2 + NEEDLE, -1.2), "quat": (0.9, 0.3, -0.2, 0.25)},
    # rotations
    "zero-quaternion": {"quat": (0.0, 0.0, 0.0, 0.0), "log_scale": (-1.5, -3.0, -2.5)},
    "unnormalised-quaternion": {"quat": (3e4, -1e4, 2e4, 5e3), "log_scale": (-1.5, -3.0, -2.5)},
    "huge-quaternion": {"quat": (1e30, 0.0, 0.0, 1e30), "log_scale": (-1.5, -3.0, -2.5)},
    "tiny-quaternion": {"quat": (1e-30, 0.0, 0.0, 1e-30), "log_scale": (-1.5, -3.0, -2.5)},
    # opacities
    "opacity-logit-plus-50": {"logit": 50.0},
    "opacity-logit-minus-50": {"logit": -50.0},
    # placement relative to the camera (at the origin, near plane z = 0.01)
    "on-the-near-plane": {"mean": (0.0, 0.0, NEAR), "log_scale": (-1.0, -1.0, -1.0)},
    "just-in-front-of-near": {"mean": (0.0, 0.0, NEAR * 1.05), "log_scale": (-6.0, -6.0, -6.0)},
    "just-in-front-of-near-big": {"mean": (0.002, -0.001, NEAR * 1.05), "log_scale": (-1.0, -1.0, -1.0)},
    "just-in-front-of-near-off-axis": {"mean": (0.05, 0.02, NEAR * 1.5), "log_scale": (-7.0, -7.0, -7.0)},
    "just-behind-near": {"mean": (0.0, 0.0, NEAR * 0.95), "log_scale": (-1.0, -1.0, -1.0)},
    "at-the-camera-centre": {"mean": (0.0, 0.0, 0.0), "log_scale": (0.0, 0.0, 0.0)},
    "behind-the-camera": {"mean": (0.1, 0.0, -1.0), "log_scale": (0.0, 0.0, 0.0)},
    "far-beside-the-view": {"mean": (1e37, 0.0, 1.0)},
    "very-far-ahead": {"mean": (0.0, 0.0, 1e6), "log_scale": (8.0, 8.0, 8.0)},
}
INVISIBLE = {
    "opacity-logit-minus-50",
    "on-the-near-plane",
    "just-behind-near",
    "at-the-camera-centre",
    "behind-the-camera",
    "far-beside-the-view",
}


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("case", sorted(DEGENERATE))
def test_degenerate_gaussian_renders_finite_and_matches_reference(backend, case):
    scene = raw_scene([*backgrounds(), DEGENERATE[case]], sh_degree=1)
    cameras = [camera()]
    out, grads = render_with_grads(scene, cameras, backend)
    assert_finite(out, grads)
    assert_matches_reference(scene, cameras, out)


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("case", sorted(INVISIBLE))
def test_invisible_gaussian_changes_nothing(backend, case):
    base = raw_scene(backgrounds(), sh_degree=1)
    scene = raw_scene([*backgrounds(), DEGENERATE[case]], sh_degree=1)
    out_base, grads_base = render_with_grads(base, [camera()], backend)
    out, grads = render_with_grads(scene, [camera()], backend)
    assert torch.equal(out.colors, out_base.colors) and torch.equal(out.alphas, out_base.alphas)
    for name, g in grads.items():
        assert torch.equal(g[:3], grads_base[name]), name
        assert not bool(g[3].any()), f"the invisible Gaussian got a gradient on {name}"


def test_cancellation_case_is_ill_conditioned_in_float32():
    """The cancellation case is real: its 2D covariance determinant a c - b^2 (a, c ~ 1e8 px^2),
    computed in float32 as 3DGS does, is wrong by more than its own size (the float64 chain is needed)."""
    scene = raw_scene([DEGENERATE["float32-cancellation-needle"]])
    cam = camera()
    x, y, z = scene.means[0].double().tolist()
    jac = torch.tensor(
        [[cam.fx / z, 0.0, -cam.fx * x / z**2], [0.0, cam.fy / z, -cam.fy * y / z**2]], dtype=torch.float64
    ) @ torch.tensor(cam.world_to_cam[:3, :3])
    dets = {}
    for dtype in (torch.float32, torch.float64):
        m = quats_to_rotmats(scene.quats.to(dtype))[0] * scene.scales.to(dtype)[0]
        j = jac.to(dtype)
        cov = j @ (m @ m.T) @ j.T + 0.3 * torch.eye(2, dtype=dtype)
        dets[dtype] = float(cov[0, 0] * cov[1, 1] - cov[0, 1] * cov[1, 0])
    assert float(cov[0, 0]) > 1e7
    assert abs(dets[torch.float32] - dets[torch.float64]) > dets[torch.float64]


@pytest.mark.parametrize("backend", BACKENDS)
def test_camera_inside_a_cloud_with_view_dependent_colour(backend):
    g = torch.Generator().manual_seed(3)
    n = 250
    rows = [
        {
            "mean": tuple(((torch.rand(3, generator=g) * 2 - 1) * 2.0).tolist()),
            "quat": tuple(torch.randn(4, generator=g).tolist()),
            "log_scale": tuple((-2.5 + 0.7 * torch.randn(3, generator=g)).tolist()),
            "logit": float(torch.randn((), generator=g)) * 2,
            "dc": tuple(torch.randn(3, generator=g).tolist()),
        }
        for _ in range(n)
    ]
    scene = raw_scene(rows, sh_degree=3)
    cameras = [camera(), camera(yaw=2.5)]
    out, grads = render_with_grads(scene, cameras, backend)
    assert_finite(out, grads)
    assert float(out.alphas.detach().min()) > 0.0  # surrounded: every pixel sees something
    assert_matches_reference(scene, cameras, out)


EMPTY = {
    "no-gaussians": [],
    "all-behind": [{"mean": (0.0, 0.0, -2.0)}, {"mean": (0.3, 0.1, -0.5), "log_scale": (0.0, 0.0, 0.0)}],
    "all-off-screen": [{"mean": (50.0, 0.0, 2.0)}, {"mean": (0.0, -40.0, 1.0)}],
    "all-transparent": [{"logit": -50.0}, {"logit": -7.0, "mean": (0.1, 0.0, 3.0)}],
}


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("case", sorted(EMPTY))
def test_empty_views_show_the_background_with_zero_gradients(backend, case):
    scene = (
        raw_scene(EMPTY[case], sh_degree=1)
        if EMPTY[case]
        else GaussianScene(
            means=torch.zeros(0, 3),
            quats=torch.zeros(0, 4),
            log_scales=torch.zeros(0, 3),
            opacity_logits=torch.zeros(0),
            sh_dc=torch.zeros(0, 3),
            sh_rest=torch.zeros(0, 3, 3),
        )
    )
    out, grads = render_with_grads(scene, [camera(), camera(yaw=0.5)], backend)
    assert_finite(out, grads)
    assert torch.equal(out.colors, torch.tensor([0.2, 0.4, 0.6]).expand_as(out.colors))
    assert not bool(out.alphas.any()) and not bool(out.depths.any())
    for name, grad in grads.items():
        assert not bool(grad.any()), name


@pytest.mark.parametrize("backend", BACKENDS)
def test_one_gaussian_filling_the_image(backend):
    scene = raw_scene([{"mean": (0.05, -0.02, 0.5), "log_scale": (1.5, 1.4, 1.2), "logit": 50.0}], sh_degree=2)
    cameras = [camera(width=64, height=48)]
    out, grads = render_with_grads(scene, cameras, backend)
    assert_finite(out, grads)
    assert float(out.alphas.detach().min()) > 0.985  # alpha is clamped at 0.99 almost everywhere
    assert_matches_reference(scene, cameras, out)


# -- the optimiser guard ----------------------------------------------------------------------------


def small_scene(n: int = 5) -> GaussianScene:
    g = torch.Generator().manual_seed(0)
    means = 0.4 * torch.randn(n, 3, generator=g) + torch.tensor([0.0, 0.0, 2.5])
    return raw_scene([{"mean": tuple(m.tolist())} for m in means], sh_degree=1)


def set_grads(opt: GaussianAdam, value: float) -> None:
    for t in opt.scene.tensors().values():
        t.grad = torch.full_like(t, value)


def test_repeated_non_finite_steps_are_logged_and_halve_the_learning_rate(caplog):
    lr = 1e-2
    opt = GaussianAdam(small_scene(), dict.fromkeys(PARAM_NAMES, lr))
    before = {k: v.detach().clone() for k, v in opt.scene.tensors().items()}
    with caplog.at_level(logging.WARNING, logger="gt2gs_blender.core.train.optim"):
        for i in range(BACKOFF_AFTER):
            set_grads(opt, math.nan if i % 2 == 0 else math.inf)
            assert not opt.step()
        assert not opt.step(loss=torch.tensor(math.nan))
    skips = [r for r in caplog.records if "step skipped" in r.getMessage()]
    assert len(skips) == BACKOFF_AFTER + 1
    assert any("learning rates scaled to 0.5" in r.getMessage() for r in caplog.records)
    assert opt.skipped == BACKOFF_AFTER + 1 and opt.steps == 0 and opt.guard.lr_scale == 0.5
    for name, t in opt.scene.tensors().items():
        assert torch.equal(t.detach(), before[name]), name
    set_grads(opt, -3.0)
    assert opt.step(loss=torch.tensor(0.5))
    for name, t in opt.scene.tensors().items():  # Adam's first step moves every value by lr (here halved)
        torch.testing.assert_close(t.detach() - before[name], torch.full_like(t, 0.5 * lr), rtol=1e-4, atol=1e-7)


def test_backoff_needs_consecutive_skips_and_has_a_floor():
    guard = StepGuard(backoff_after=2)
    grads = {"x": torch.ones(3)}
    for _ in range(5):  # skip, allow, skip, allow ...: never two in a row
        assert not guard.allow(math.nan, grads)
        assert guard.allow(1.0, grads)
    assert guard.lr_scale == 1.0 and guard.skipped == 5
    for _ in range(100):
        guard.allow(1.0, {"x": torch.tensor([0.0, math.inf])})
    assert guard.lr_scale == 2.0**-10


def test_an_update_that_would_overflow_is_skipped():
    scene = small_scene(2)
    scene = replace(scene, means=torch.tensor([[3e38, 0.0, 1.0], [0.0, 0.0, 1.0]]))
    opt = GaussianAdam(scene, dict.fromkeys(PARAM_NAMES, 1e38))
    set_grads(opt, -1.0)
    before = {k: v.detach().clone() for k, v in opt.scene.tensors().items()}
    assert not opt.step(loss=torch.tensor(1.0))
    assert opt.steps == 0 and opt.skipped == 1
    for name, t in opt.scene.tensors().items():
        assert torch.equal(t.detach(), before[name]), name
    assert not bool(opt.exp_avg["means"].any())  # the moments did not move either


def test_a_fit_with_non_finite_losses_never_writes_nan_into_the_scene(caplog):
    target = small_scene(12)
    cameras = [camera(yaw=a) for a in (-0.3, 0.0, 0.3)]
    with torch.no_grad():
        images = render(target, cameras, background=(0.0, 0.0, 0.0), render_depth=False, backend="torch").colors
    images[1, 5, 7] = math.nan  # one corrupt training pixel: that view's loss is NaN every time
    start = replace(target, sh_dc=target.sh_dc + 0.5)
    trainer = Trainer(start, cameras, images, FitConfig(iterations=9, densify_until=0, backend="torch"), extent=1.0)
    with caplog.at_level(logging.WARNING, logger="gt2gs_blender.core.train.optim"):
        scene = trainer.run()
    assert trainer.opt.skipped == 3 and trainer.opt.steps == 6  # each of the 3 views is drawn 3 times
    assert len([r for r in caplog.records if "step skipped" in r.getMessage()]) == 3
    for name, t in scene.tensors().items():
        assert bool(torch.isfinite(t).all()), name
    assert not torch.equal(scene.sh_dc, start.sh_dc)  # the finite steps did train


# -- densification of absurd scales -----------------------------------------------------------------

FLOAT32_MAX_LOG = math.log(torch.finfo(torch.float32).max)
ABSURD_LOG_SCALES = {
    "scale-e80": (80.0, 80.0, 79.0),
    "scale-e80-needle": (80.0, -80.0, -80.0),
    "scale-overflows": (100.0, 2.0, 2.0),
    "log-scale-float32-max": (3.4e38, 0.0, 0.0),
    "scale-1e-30": (math.log(1e-30),) * 3,
    "scale-zero": (-1e4, -1e4, -1e4),
    "log-scale-float32-min": (-3.4e38, -3.4e38, -3.4e38),
    "ordinary": (-1.0, -1.5, -2.0),
}


@pytest.mark.parametrize("percent_dense", [0.01, 0.0])
def test_densifying_absurd_scales_keeps_every_value_finite(percent_dense, caplog):
    """Split children are sampled from their parent: exp(100) overflows, so such a parent stays unsplit
    (counted, logged, bit-identical); everything else splits or clones into finite values. With
    percent_dense 0 even the tiny ones are split."""
    names = sorted(ABSURD_LOG_SCALES)
    rows = [
        {"mean": (0.1 * i, -0.05 * i, 2.0), "log_scale": ABSURD_LOG_SCALES[name], "quat": (0.9, 0.3, -0.2, 0.25)}
        for i, name in enumerate(names)
    ]
    opt = GaussianAdam(raw_scene(rows), dict.fromkeys(PARAM_NAMES, 1e-3))
    before = {k: v.detach().clone() for k, v in opt.scene.tensors().items()}
    stats = DensityStats(len(rows))
    stats.grad_sum[:], stats.count[:] = 1.0, 1  # every Gaussian is due to grow
    with caplog.at_level(logging.WARNING, logger="gt2gs_blender.core.train.densify"):
        report = densify_and_prune(
            opt,
            stats,
            DensifyConfig(percent_dense=percent_dense),
            1.0,
            prune_large=False,
            generator=torch.Generator().manual_seed(0),
        )
    for name, t in opt.scene.tensors().items():
        assert bool(torch.isfinite(t).all()), name
    overflowing = [i for i, name in enumerate(names) if max(ABSURD_LOG_SCALES[name]) > FLOAT32_MAX_LOG]
    small = [
        i for i, name in enumerate(names) if float(torch.tensor(ABSURD_LOG_SCALES[name]).exp().max()) <= percent_dense
    ]
    assert report.unsplit == len(overflowing) == 2 and report.pruned == 0
    assert report.cloned == len(small) and report.split == len(rows) - len(small) - len(overflowing)
    assert report.total == len(opt.scene) == len(rows) + report.cloned + report.split
    assert any(f"{len(overflowing)} Gaussians were not split" in r.getMessage() for r in caplog.records)
    survivors = sorted(overflowing + small)  # first, in their order, exactly as they were
    after = {k: v.detach() for k, v in opt.scene.tensors().items()}
    for name, t in after.items():
        assert torch.equal(t[: len(survivors)], before[name][survivors]), name
        assert torch.equal(t[len(survivors) : len(survivors) + len(small)], before[name][small]), name  # clones
    parents = torch.tensor([i for i in range(len(rows)) if i not in survivors]).repeat_interleave(2)
    children = after["log_scales"][len(survivors) + len(small) :]
    assert torch.allclose(children, before["log_scales"][parents] - math.log(1.6))
