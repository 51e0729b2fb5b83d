"""The fit engine: Adam and its masks, a one-Gaussian fit, the loss on real photos, the fit command."""

from __future__ import annotations

import json
import math

import pytest
import torch

from gt2gs_blender.app.cli import main as cli
from gt2gs_blender.core.cameras.cameras_json import load_cameras_json
from gt2gs_blender.core.cameras.llff import load_llff
from gt2gs_blender.core.cameras.poses import orbit_views
from gt2gs_blender.core.fit.init import frustum_points, knn_scales, scene_from_points
from gt2gs_blender.core.fit.trainer import FitConfig, Trainer, evaluate, llff_split, load_images
from gt2gs_blender.core.render import render
from gt2gs_blender.core.scene.gaussians import GaussianScene, quats_to_rotmats
from gt2gs_blender.core.scene.ply import read_ply
from gt2gs_blender.core.train.densify import DensifyConfig
from gt2gs_blender.core.train.optim import PARAM_NAMES, GaussianAdam, LearningRates, exponential_decay
from gt2gs_blender.core.train.reconstruction import reconstruction_loss, window_max
from gt2gs_blender.core.train.ssim import WINDOW

FAST_LRS = LearningRates(means=3e-3, means_final=3e-4, quats=1e-2, log_scales=1e-2, sh_dc=1e-2)
"""Learning rates for tiny synthetic fits (3DGS's are tuned for 30k steps)."""


def random_scene(n: int, seed: int = 0, spread: float = 0.5) -> GaussianScene:
    g = torch.Generator().manual_seed(seed)
    return GaussianScene.from_activated(
        (torch.rand(n, 3, generator=g) - 0.5) * 2 * spread,
        torch.rand(n, 3, generator=g) * 0.1 + 0.03,
        torch.rand(n, generator=g) * 0.8 + 0.1,
        torch.rand(n, 3, generator=g),
        sh_degree=1,
    )


def views(n: int = 6, size: int = 32):
    return orbit_views((0.0, 0.0, 0.0), 3.0, n, width=size, height=size, fov_deg=40.0, elevation_deg=25.0)


def renders(scene: GaussianScene, cameras) -> torch.Tensor:
    with torch.no_grad():
        return render(scene, cameras, background=(0.0, 0.0, 0.0), render_depth=False).colors


def covariance(scene: GaussianScene) -> torch.Tensor:
    m = quats_to_rotmats(scene.quats) * scene.scales[:, None, :]
    return m @ m.transpose(1, 2)


# -- optimiser --------------------------------------------------------------------------------------


def test_exponential_decay_runs_log_linearly_between_its_ends():
    assert exponential_decay(0, 100, 1e-2, 1e-4) == pytest.approx(1e-2)
    assert exponential_decay(50, 100, 1e-2, 1e-4) == pytest.approx(1e-3)
    assert exponential_decay(100, 100, 1e-2, 1e-4) == exponential_decay(500, 100, 1e-2, 1e-4) == pytest.approx(1e-4)
    lrs = LearningRates().at(0, 10, extent=5.0)
    assert lrs["means"] == pytest.approx(8e-4) and lrs["sh_rest"] == pytest.approx(lrs["sh_dc"] / 20)


def test_adam_matches_torch_adam():
    scene = random_scene(20)
    lrs = {name: 1e-3 * (i + 1) for i, name in enumerate(PARAM_NAMES)}
    ours = GaussianAdam(scene, lrs)
    reference = {k: v.detach().clone().requires_grad_() for k, v in scene.tensors().items()}
    torch_adam = torch.optim.Adam([{"params": [reference[k]], "lr": lrs[k]} for k in PARAM_NAMES], eps=1e-15)
    g = torch.Generator().manual_seed(1)
    for _ in range(5):
        for name in PARAM_NAMES:
            grad = torch.randn(reference[name].shape, generator=g)
            ours.scene.tensors()[name].grad = grad
            reference[name].grad = grad.clone()
        assert ours.step()
        torch_adam.step()
    for name in PARAM_NAMES:
        torch.testing.assert_close(ours.scene.tensors()[name], reference[name], rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("shared", [True, False])
def test_shared_channels_step_each_colour_where_its_momentum_points(shared):
    """``shared_channels``: after a history that differs per channel (R alone, then grey gradients), each colour's
    step is its momentum times one positive number for R, G and B, by a float64 re-derivation of Adam with the
    second moment's channel mean as divisor; per element (not shared) the same history turns the step's hue away."""
    scene = random_scene(12)
    colours = ("sh_dc", "sh_rest")
    lr = 1e-2
    opt = GaussianAdam(
        scene, dict.fromkeys(PARAM_NAMES, lr), trainable=colours, shared_channels=colours if shared else ()
    )
    g = torch.Generator().manual_seed(3)
    m = {k: torch.zeros_like(getattr(scene, k), dtype=torch.float64) for k in colours}
    v = {k: torch.zeros_like(m[k]) for k in colours}
    expected = {k: getattr(scene, k).detach().double().clone() for k in colours}
    for step in range(6):
        before = {k: getattr(opt.scene, k).detach().double().clone() for k in colours}
        for k in colours:
            grad = torch.randn(getattr(scene, k).shape, generator=g)
            grad = grad * torch.tensor([1.0, 0.0, 0.0]) if step < 3 else grad[..., :1].expand_as(grad).clone()
            getattr(opt.scene, k).grad = grad
            m[k] = 0.9 * m[k] + 0.1 * grad.double()
            v[k] = 0.999 * v[k] + 0.001 * grad.double() ** 2
        assert opt.step()
        bc1, bc2 = 1 - 0.9 ** (step + 1), 1 - 0.999 ** (step + 1)
        for k in colours:
            divisor = (v[k] / bc2).mean(-1, keepdim=True) if shared else v[k] / bc2
            expected[k] -= lr * (m[k] / bc1) / (divisor.sqrt() + 1e-15)
            torch.testing.assert_close(getattr(opt.scene, k).detach().double(), expected[k], rtol=1e-5, atol=1e-6)
    for k in colours:
        moved = before[k] - getattr(opt.scene, k).detach().double()
        ratio = moved / m[k]
        spread = float((ratio - ratio.mean(-1, keepdim=True)).abs().max() / ratio.abs().max())
        assert bool((ratio > 0).all())
        assert (spread < 1e-4) if shared else (spread > 0.1), (k, spread)


def test_frozen_gaussians_with_momentum_do_not_move():
    opt = GaussianAdam(random_scene(30), dict.fromkeys(PARAM_NAMES, 1e-2))
    g = torch.Generator().manual_seed(2)

    def noisy_steps(count: int) -> None:
        for _ in range(count):
            for t in opt.scene.tensors().values():
                t.grad = torch.randn(t.shape, generator=g)
            opt.step()

    noisy_steps(5)
    frozen = torch.arange(30) % 3 == 0
    opt.frozen = frozen
    before = {k: v.detach().clone() for k, v in opt.scene.tensors().items()}
    noisy_steps(20)
    for name, t in opt.scene.tensors().items():
        assert torch.equal(t.detach()[frozen], before[name][frozen]), name
        assert not torch.equal(t.detach()[~frozen], before[name][~frozen]), name


def test_non_finite_loss_or_gradient_skips_the_step():
    opt = GaussianAdam(random_scene(4), dict.fromkeys(PARAM_NAMES, 1e-2))
    before = {k: v.detach().clone() for k, v in opt.scene.tensors().items()}
    for t in opt.scene.tensors().values():
        t.grad = torch.ones_like(t)
    opt.scene.means.grad[2, 1] = math.nan
    assert not opt.step()
    opt.scene.means.grad[2, 1] = 0.0
    assert not opt.step(loss=torch.tensor(math.inf))
    assert opt.skipped == 2 and opt.steps == 0
    for name, t in opt.scene.tensors().items():
        assert torch.equal(t.detach(), before[name]), name
    assert opt.step(loss=torch.tensor(1.0)) and opt.steps == 1


def test_at_rest_until_a_gradient_gives_momentum_to_a_trained_tensor():
    """A step with no gradient moves nothing exactly while every trained tensor's first moment is zero, and only
    then: ``at_rest`` is what lets a caller take such a step without computing its gradient."""
    opt = GaussianAdam(random_scene(6), dict.fromkeys(PARAM_NAMES, 1e-2))
    before = {k: v.detach().clone() for k, v in opt.scene.tensors().items()}
    assert opt.at_rest()
    assert opt.step(loss=torch.tensor(0.5)) and opt.at_rest() and opt.steps == 1
    for name, t in opt.scene.tensors().items():
        assert torch.equal(t.detach(), before[name]), name
    opt.set_trainable({"sh_dc"})
    opt.scene.sh_dc.grad = torch.zeros_like(opt.scene.sh_dc)
    opt.scene.sh_dc.grad[3, 0] = 1e-3
    assert opt.step() and not opt.at_rest()
    opt.zero_grad()
    moved = opt.scene.sh_dc.detach().clone()
    assert opt.step() and not torch.equal(opt.scene.sh_dc.detach(), moved)  # momentum moves it without a gradient
    opt.set_trainable({"means", "log_scales"})  # the colour's momentum is not theirs
    assert opt.at_rest()


def test_an_idle_step_is_a_step_without_a_gradient_bit_for_bit():
    """``idle_step`` (what a caller takes while ``at_rest``) against ``step`` with no gradient, the oracle, from a
    state with second moments to decay and frozen rows that keep theirs: the same tensors, moments and count."""
    frozen = torch.zeros(8, dtype=torch.bool)
    frozen[[1, 5]] = True
    stepping = GaussianAdam(random_scene(8), dict.fromkeys(PARAM_NAMES, 1e-2), frozen=frozen)
    for t in stepping.scene.tensors().values():
        t.grad = torch.randn_like(t)
    assert stepping.step(loss=torch.tensor(1.0))
    stepping.zero_grad()
    for name in PARAM_NAMES:
        stepping.exp_avg[name].zero_()  # at rest, with second moments left ...
        stepping.exp_avg_sq[name][frozen] = 0.5  # ... also on frozen rows, which keep theirs
    stepping.set_trainable({"means", "log_scales", "quats", "opacity_logits"})
    idle = GaussianAdam(stepping.scene, dict(stepping.lrs), trainable=stepping.trainable, frozen=frozen)
    idle.exp_avg = {k: v.clone() for k, v in stepping.exp_avg.items()}
    idle.exp_avg_sq = {k: v.clone() for k, v in stepping.exp_avg_sq.items()}
    idle.steps = stepping.steps
    assert stepping.at_rest() and idle.at_rest()
    for _ in range(3):
        assert stepping.step(loss=torch.tensor(0.25))
        idle.idle_step()
    assert idle.steps == stepping.steps == 4
    for name, t in stepping.scene.tensors().items():
        assert torch.equal(idle.scene.tensors()[name].detach(), t.detach()), name
        assert torch.equal(idle.exp_avg[name], stepping.exp_avg[name]), name
        assert torch.equal(idle.exp_avg_sq[name], stepping.exp_avg_sq[name]), name
    assert not torch.equal(stepping.exp_avg_sq["means"][0], torch.zeros(3))  # decayed, not cleared


def test_only_trainable_tensors_change():
    target = random_scene(40, seed=1)
    cameras = views(4)
    start = random_scene(40, seed=2)
    trainer = Trainer(
        start, cameras, renders(target, cameras), FitConfig(iterations=10, densify_until=0), trainable={"sh_dc"}
    )
    scene = trainer.run()
    for name, t in scene.tensors().items():
        assert torch.equal(t, start.tensors()[name]) == (name != "sh_dc"), name


# -- fitting ----------------------------------------------------------------------------------------


def test_one_gaussian_fit_recovers_the_target():
    """Render a known Gaussian from 6 views, start from a perturbed isotropic one, recover position,
    covariance and opacity x colour (the only colour quantity one Gaussian over black determines)."""
    target = GaussianScene.from_activated(
        torch.tensor([[0.1, -0.05, 0.0]]),
        torch.tensor([[0.3, 0.15, 0.08]]),
        torch.tensor([0.8]),
        torch.tensor([[0.9, 0.4, 0.2]]),
        quats=torch.tensor([[0.9, 0.2, -0.3, 0.1]]),
    )
    start = GaussianScene.from_activated(
        torch.tensor([[0.0, 0.0, 0.1]]), torch.full((1, 3), 0.2), torch.tensor([0.5]), torch.full((1, 3), 0.5)
    )
    cameras = views(6, size=40)
    config = FitConfig(iterations=300, densify_until=0, sh_interval=0, lrs=FAST_LRS)
    fitted = Trainer(start, cameras, renders(target, cameras), config).run()
    torch.testing.assert_close(fitted.means, target.means, atol=3e-3, rtol=0)
    torch.testing.assert_close(covariance(fitted), covariance(target), atol=3e-3, rtol=0)
    torch.testing.assert_close(
        fitted.opacities[:, None] * fitted.base_colors,
        target.opacities[:, None] * target.base_colors,
        atol=0.01,
        rtol=0,
    )


def test_frozen_gaussians_are_bit_identical_through_densification():
    target, start = random_scene(120, seed=3), random_scene(120, seed=4)
    start.extras = {"tag": torch.arange(120).numpy()}
    cameras = views(6)
    frozen = torch.arange(120) % 4 == 0
    config = FitConfig(
        iterations=60,
        densify_from=5,
        densify_every=10,
        densify_until=60,
        opacity_reset_every=30,
        lrs=FAST_LRS,
        densify=DensifyConfig(grad_threshold=1e-6),
    )
    trainer = Trainer(start, cameras, renders(target, cameras), config, frozen=frozen, extent=1.0)
    scene = trainer.run()
    assert len(scene) != len(start)  # densification and pruning did happen
    rows = trainer.opt.frozen
    assert int(rows.sum()) == int(frozen.sum())
    for name, t in scene.tensors().items():
        assert torch.equal(t[rows], start.tensors()[name][frozen]), name
    assert (scene.extras["tag"][rows.numpy()] == start.extras["tag"][frozen.numpy()]).all()


def test_render_colors_attachment_is_rendered_and_follows_densification():
    target = random_scene(60, seed=5)
    cameras = views(4)
    wrong = GaussianScene(**{**target.tensors(), "sh_dc": torch.zeros(60, 3)})
    config = FitConfig(
        iterations=20, densify_from=0, densify_every=10, lrs=FAST_LRS, densify=DensifyConfig(grad_threshold=1e-7)
    )
    trainer = Trainer(
        wrong,
        cameras,
        renders(target, cameras),
        config,
        trainable={"means", "log_scales"},
        attachments={"c_g": target.base_colors},
        render_colors="c_g",
        extent=1.0,
    )
    assert trainer.step() < 1e-3
    trainer.run()
    assert trainer.opt.attachments["c_g"].shape == (len(trainer.scene), 3) and len(trainer.scene) > 60


def test_knn_scales_and_point_initialisation():
    grid = torch.stack(torch.meshgrid(*[torch.arange(6.0)] * 3, indexing="ij"), -1).reshape(-1, 3) * 0.5
    scales = knn_scales(grid)
    assert torch.allclose(scales, torch.full_like(scales, 0.5))
    scene = scene_from_points(grid, torch.full((216, 3), 0.25), sh_degree=1)
    assert torch.allclose(scene.opacities, torch.full((216,), 0.1)) and scene.sh_degree == 1
    assert torch.allclose(scene.base_colors, torch.full((216, 3), 0.25), atol=1e-6)


def test_frustum_points_lie_in_the_views_between_the_bounds():
    cameras = views(3)
    points, colors, scales = frustum_points(
        cameras, [2.0] * 3, [4.0] * 3, 500, generator=torch.Generator().manual_seed(0)
    )
    assert points.shape == (500, 3) and colors.shape == (500, 3) and bool((scales > 0).all())
    seen = torch.zeros(500, dtype=torch.bool)
    for camera in cameras:
        uv, depth = camera.project(points.double().numpy())
        uv, depth = torch.from_numpy(uv), torch.from_numpy(depth)
        inside = (
            (depth > 2.0 - 1e-4)
            & (depth < 4.0 + 1e-4)
            & (uv >= 0).all(1)
            & (uv[:, 0] <= camera.width)
            & (uv[:, 1] <= camera.height)
        )
        seen |= inside
    assert bool(seen.all())


def test_evaluate_a_perfect_render():
    scene, cameras = random_scene(50), views(2)
    metrics = evaluate(scene, cameras, renders(scene, cameras).clamp(0, 1))
    assert metrics.psnr > 60 and metrics.ssim == pytest.approx(1.0) and len(metrics.per_view) == 2


def test_llff_split_holds_out_every_eighth_view():
    train, test = llff_split(20)
    assert test == [0, 8, 16] and len(train) == 17 and not set(train) & set(test)


# -- real photos ------------------------------------------------------------------------------------


def test_loss_decreases_on_a_tiny_real_crop(shared):
    data = load_llff(shared / "data" / "scenes" / "fern_llff", downscale=32, image_dir="images_8")
    cameras = data.cameras[1:5]
    images = load_images(data.image_paths[1:5], cameras[0].width, cameras[0].height)
    points, colors, scales = frustum_points(
        cameras,
        data.bounds[1:5, 0],
        data.bounds[1:5, 1],
        3000,
        images=images,
        generator=torch.Generator().manual_seed(0),
    )
    trainer = Trainer(
        scene_from_points(points, colors, scales=scales), cameras, images, FitConfig(iterations=60, densify_until=0)
    )
    losses = [trainer.step() for _ in range(60)]
    first, last = sum(losses[:10]) / 10, sum(losses[-10:]) / 10
    assert last < 0.8 * first
    rendered = renders(trainer.scene.detach(), cameras[:1])
    assert float(reconstruction_loss(rendered[0], images[0])) < first


def test_fit_command_writes_the_inria_layout_and_a_report(shared, tmp_path, capsys):
    out, report = tmp_path / "fern", tmp_path / "report.json"
    code = cli.main(
        [
            "fit",
            str(shared / "data" / "scenes" / "fern_llff"),
            "--out",
            str(out),
            "--iterations",
            "20",
            "--downscale",
            "32",
            "--points",
            "2000",
            "--report",
            str(report),
        ]
    )
    stdout, stderr = capsys.readouterr()
    assert code == 0, stderr
    values = json.loads(report.read_text())
    assert {"test_psnr", "test_ssim", "seconds", "n_gaussians"} <= set(values)
    assert values["test_psnr"] > 5 and 0 < values["test_ssim"] <= 1
    assert "PSNR" in stdout and "SSIM" in stdout
    scene = read_ply(out / "point_cloud.ply")
    assert (
        len(scene) == values["n_gaussians"] == len(read_ply(out / "point_cloud" / "iteration_20" / "point_cloud.ply"))
    )
    assert len(load_cameras_json(out / "cameras.json")) == 20


def test_reconstruction_tolerance_passes_no_gradient_below_it_and_the_same_direction_above():
    """Residuals within the tolerance give exactly zero gradient (Adam would turn any gradient into a
    full step); large residuals give nearly the plain loss's gradient."""
    generator = torch.Generator().manual_seed(0)
    target = torch.rand(24, 24, 3, generator=generator)
    tiny = (target + 1e-4 * torch.randn(24, 24, 3, generator=generator)).requires_grad_()
    reconstruction_loss(tiny, target, tolerance=0.5 / 255).backward()
    assert tiny.grad.abs().max() == 0
    reconstruction_loss(tiny, target).backward()
    assert tiny.grad.abs().max() > 0
    far = (target + 0.2 * torch.randn(24, 24, 3, generator=generator)).requires_grad_()
    grads = [
        torch.autograd.grad(reconstruction_loss(far, target, tolerance=t), far)[0].flatten() for t in (0.0, 0.5 / 255)
    ]
    assert torch.nn.functional.cosine_similarity(grads[0], grads[1], dim=0) > 0.99


def test_window_max_equals_a_2d_max_pool():
    """The separable window maximum the tolerance uses is exactly one 2D max pool over the SSIM window."""
    images = torch.rand(2, 3, 40, 33, generator=torch.Generator().manual_seed(1))
    assert torch.equal(window_max(images), torch.nn.functional.max_pool2d(images, WINDOW, stride=1))
