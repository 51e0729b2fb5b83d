"""Density control keeps every per-Gaussian tensor aligned: parameters, Adam moments, masks, stats."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from gt2gs_blender.core.render.projection import Footprints
from gt2gs_blender.core.scene.gaussians import GaussianScene
from gt2gs_blender.core.train.densify import (
    DensifyConfig,
    DensityStats,
    apply_structure,
    densify_and_prune,
    reset_opacity,
)
from gt2gs_blender.core.train.optim import PARAM_NAMES, GaussianAdam

EXTENT = 2.0
CONFIG = DensifyConfig()


def random_scene(n: int, seed: int) -> GaussianScene:
    """n Gaussians with every tensor random, SH degree 1 and one extra property."""
    g = torch.Generator().manual_seed(seed)
    return GaussianScene(
        means=torch.randn(n, 3, generator=g),
        quats=torch.randn(n, 4, generator=g),
        log_scales=torch.randn(n, 3, generator=g) - 4.0,
        opacity_logits=torch.randn(n, generator=g) * 3,
        sh_dc=torch.randn(n, 3, generator=g),
        sh_rest=torch.randn(n, 3, 3, generator=g),
        extras={"nx": np.arange(n, dtype=np.float32)},
    )


def trained_optimizer(n: int, seed: int, frozen: torch.Tensor) -> GaussianAdam:
    """An optimiser with non-zero moments on every row, a frozen mask and an attachment."""
    opt = GaussianAdam(
        random_scene(n, seed),
        dict.fromkeys(PARAM_NAMES, 1e-3),
        frozen=frozen,
        attachments={"c_g": torch.arange(n, dtype=torch.float32)[:, None].repeat(1, 3)},
    )
    g = torch.Generator().manual_seed(seed + 1)
    for name in PARAM_NAMES:
        opt.exp_avg[name] = torch.randn(opt.exp_avg[name].shape, generator=g)
        opt.exp_avg_sq[name] = torch.rand(opt.exp_avg_sq[name].shape, generator=g)
    return opt


def random_stats(n: int, seed: int) -> DensityStats:
    g = torch.Generator().manual_seed(seed + 2)
    stats = DensityStats(n)
    stats.grad_sum = torch.rand(n, generator=g, dtype=torch.float64) * 1e-3
    stats.count = torch.randint(0, 5, (n,), generator=g)
    stats.max_radius = torch.rand(n, generator=g) * 40
    return stats


def snapshot(opt: GaussianAdam) -> dict[str, torch.Tensor]:
    """Every per-Gaussian tensor of the optimiser, by name, copied."""
    out = {f"param.{k}": v.detach().clone() for k, v in opt.scene.tensors().items()}
    out |= {f"m.{k}": v.clone() for k, v in opt.exp_avg.items()}
    out |= {f"v.{k}": v.clone() for k, v in opt.exp_avg_sq.items()}
    out |= {
        "frozen": opt.frozen.clone(),
        "c_g": opt.attachments["c_g"].clone(),
        "nx": torch.from_numpy(opt.scene.extras["nx"].copy()),
    }
    return out


def assert_aligned(opt: GaussianAdam, stats: DensityStats) -> None:
    n = len(opt.scene)
    for name, t in snapshot(opt).items():
        assert t.shape[0] == n, name
    assert len(stats) == n
    for name, t in opt.scene.tensors().items():
        assert t.is_leaf and t.requires_grad, name


masks = st.integers(1, 24).flatmap(
    lambda n: st.tuples(
        st.just(n),
        st.lists(st.booleans(), min_size=n, max_size=n),
        st.lists(st.booleans(), min_size=n, max_size=n),
        st.lists(st.integers(0, n - 1), max_size=12),
        st.integers(0, 2**16),
    )
)


@settings(max_examples=60, deadline=None)
@given(masks)
def test_restructure_keeps_survivors_and_zeroes_new_rows(case):
    n, keep, frozen, parents, seed = case
    keep, frozen, parents = torch.tensor(keep), torch.tensor(frozen), torch.tensor(parents, dtype=torch.long)
    opt, stats = trained_optimizer(n, seed, frozen), random_stats(n, seed)
    before, stats_before = snapshot(opt), (stats.grad_sum.clone(), stats.count.clone(), stats.max_radius.clone())
    new_means = torch.randn(len(parents), 3)
    apply_structure(opt, stats, keep, parents, {"means": new_means})
    assert_aligned(opt, stats)
    kept = int(keep.sum())
    assert len(opt.scene) == kept + len(parents)
    after = snapshot(opt)
    for name, old in before.items():
        assert torch.equal(after[name][:kept], old[keep]), name
        if name.startswith(("m.", "v.")):
            assert not after[name][kept:].any(), name
        elif name != "param.means":
            assert torch.equal(after[name][kept:], old[parents]), name
    assert torch.equal(after["param.means"][kept:], new_means)
    for new, old in zip((stats.grad_sum, stats.count, stats.max_radius), stats_before):
        assert torch.equal(new[:kept], old[keep]) and not new[kept:].any()


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 30), st.integers(0, 2**16), st.floats(0.0, 1.0), st.booleans())
def test_densify_and_prune_accounts_for_every_gaussian(n, seed, frozen_fraction, prune_large):
    frozen = torch.rand(n, generator=torch.Generator().manual_seed(seed)) < frozen_fraction
    opt, stats = trained_optimizer(n, seed, frozen), random_stats(n, seed)
    before = snapshot(opt)
    grads = stats.mean_grad()
    report = densify_and_prune(
        opt, stats, CONFIG, EXTENT, prune_large=prune_large, generator=torch.Generator().manual_seed(seed)
    )
    assert_aligned(opt, stats)
    assert report.total == len(opt.scene) == n - report.pruned - report.split + report.cloned + 2 * report.split
    assert not stats.count.any() and not stats.grad_sum.any()
    # Survivors come first, in order, untouched; frozen Gaussians all survive and stay frozen.
    survivors = n - report.pruned - report.split
    after = snapshot(opt)
    old_rows = (after["nx"][:survivors]).long()
    for name, old in before.items():
        assert torch.equal(after[name][:survivors], old[old_rows]), name
    assert set(torch.nonzero(before["frozen"]).squeeze(1).tolist()) <= set(old_rows.tolist())
    assert not after["frozen"][survivors:].any()
    # Every grown Gaussian had a large gradient; split children are 1.6x smaller than their parent.
    parents = after["nx"][survivors:].long()
    assert bool((grads[parents] >= CONFIG.grad_threshold).all())
    split_children = after["param.log_scales"][survivors:] != before["param.log_scales"][parents]
    assert torch.allclose(
        after["param.log_scales"][survivors:][split_children],
        (before["param.log_scales"][parents] - math.log(1.6))[split_children],
    )


@pytest.mark.parametrize("clone", [True, False])
def test_small_is_cloned_large_is_split_faint_is_pruned(clone):
    """``clone`` off (a colour-only run) leaves the small one as it is; the large one still splits."""
    scene = GaussianScene.from_activated(
        torch.zeros(4, 3),
        torch.tensor([[0.001] * 3, [0.5] * 3, [0.001] * 3, [0.001] * 3]),
        torch.tensor([0.5, 0.5, 0.001, 0.5]),
        torch.full((4, 3), 0.5),
    )
    opt = GaussianAdam(scene, dict.fromkeys(PARAM_NAMES, 1e-3))
    stats = DensityStats(4)
    stats.grad_sum[:] = torch.tensor([1.0, 1.0, 1.0, 0.0])
    stats.count[:] = 1
    report = densify_and_prune(
        opt, stats, replace(CONFIG, clone=clone), EXTENT, prune_large=False, generator=torch.Generator().manual_seed(0)
    )
    clones = int(clone)
    assert (report.cloned, report.split, report.pruned, report.total) == (clones, 1, 1, 4 + clones)
    scales = opt.scene.scales.detach()
    assert torch.allclose(scales[: 2 + clones, 0], torch.full((2 + clones,), 0.001))
    assert torch.allclose(scales[2 + clones :, 0], torch.full((2,), 0.5 / 1.6))
    assert bool((opt.scene.means[2 + clones :].detach().abs() < 0.5 * 5).all())


def test_prune_large_by_screen_and_world_size():
    scene = GaussianScene.from_activated(
        torch.zeros(3, 3),
        torch.tensor([[0.01] * 3, [0.01] * 3, [0.3] * 3]),
        torch.full((3,), 0.5),
        torch.full((3, 3), 0.5),
    )
    for prune_large, expected in ((False, 3), (True, 1)):
        opt, stats = GaussianAdam(scene, dict.fromkeys(PARAM_NAMES, 1e-3)), DensityStats(3)
        stats.max_radius[:] = torch.tensor([5.0, 25.0, 5.0])
        densify_and_prune(opt, stats, CONFIG, EXTENT, prune_large=prune_large)
        assert len(opt.scene) == expected


def footprints(gauss_ids: list[int], means2d_grad: list[list[float]], radii: list[float]) -> Footprints:
    m = len(gauss_ids)
    means2d = torch.zeros(m, 2, requires_grad=True)
    means2d.grad = torch.tensor(means2d_grad)
    return Footprints(
        cam_ids=torch.zeros(m, dtype=torch.long),
        gauss_ids=torch.tensor(gauss_ids),
        means2d=means2d,
        radii=torch.tensor(radii)[:, None].repeat(1, 2),
    )


def test_position_statistics_are_ndc_gradient_norms():
    stats = DensityStats(3, "position")
    stats.add(footprints([0, 2], [[1.0, 0.0], [0.0, 2.0]], [3.0, 7.0]), width=100, height=50, sh_dc_grad=None)
    stats.add(footprints([0], [[0.0, 1.0]], [4.0]), width=100, height=50, sh_dc_grad=None)
    assert stats.count.tolist() == [2, 0, 1]
    assert torch.allclose(stats.mean_grad(), torch.tensor([(50.0 + 25.0) / 2, 0.0, 50.0], dtype=torch.float64))
    assert stats.max_radius.tolist() == [4.0, 0.0, 7.0]


def test_color_statistics_are_dc_gradient_norms_of_visible_gaussians():
    stats = DensityStats(3, "color")
    dc_grad = torch.tensor([[3.0, 4.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 2.0]])
    stats.add(footprints([0, 2, 0], [[0.0, 0.0]] * 3, [1.0, 1.0, 1.0]), 10, 10, sh_dc_grad=dc_grad)
    assert stats.count.tolist() == [1, 0, 1]
    assert torch.allclose(stats.mean_grad(), torch.tensor([5.0, 0.0, 2.0], dtype=torch.float64))


def test_opacity_reset_caps_unfrozen_and_restarts_their_moments():
    frozen = torch.tensor([False, True, False])
    opt = trained_optimizer(3, 0, frozen)
    opt.scene.opacity_logits.data[:] = torch.tensor([3.0, 3.0, -6.0])
    moments = opt.exp_avg["opacity_logits"].clone()
    reset_opacity(opt, 0.01)
    logits = opt.scene.opacity_logits.detach()
    assert logits[0] == pytest.approx(math.log(0.01 / 0.99)) and logits[1] == 3.0 and logits[2] == -6.0
    assert opt.exp_avg["opacity_logits"][[0, 2]].eq(0).all() and opt.exp_avg["opacity_logits"][1] == moments[1]


def test_unknown_gradient_source_is_rejected():
    with pytest.raises(ValueError, match="gradient source"):
        DensifyConfig(grad_source="depth")


def test_the_densification_schedule_is_every_n_steps_past_the_start():
    """One schedule for photo fitting (3DGS: from step 500, every 100) and the stylise phases (every 25)."""
    from gt2gs_blender.core.train.densify import densify_due

    assert [s for s in range(1, 101) if densify_due(s, 25)] == [25, 50, 75, 100]
    assert [s for s in range(1, 1001) if densify_due(s, 100, after=500)] == [600, 700, 800, 900, 1000]
