"""The speed work's behaviour: matching per angle and on covered cells gives the same targets, and
hidden Gaussians are skipped (left out of rendering and optimisation, returned unchanged)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from gt2gs_blender.core.cameras.generate import auto_views
from gt2gs_blender.core.scene.gaussians import GaussianScene
from gt2gs_blender.core.transfer import stylise as stylise_module
from gt2gs_blender.core.transfer.content import contributions, hidden_gaussians
from gt2gs_blender.core.transfer.gt2 import angle_distance, match_with_prior
from gt2gs_blender.core.transfer.pipeline import transfer
from gt2gs_blender.core.transfer.texture_bank import TextureBank
from gt2gs_blender.core.transfer.views import fit_cameras

from .test_transfer import blob_scene, stripes, tiny


def brute_force_match(
    feats: torch.Tensor, bank: TextureBank, prior: torch.Tensor, lambda_prior: float, groups: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """Reference: every cell against every row of its group, the full cost matrix at once."""
    c = feats.shape[0]
    queries = F.normalize(feats.reshape(c, -1).T, dim=1)
    rows = F.normalize(bank.features, dim=1)
    cost = 1.0 - queries @ rows.T
    flat_groups = groups.reshape(-1)
    allowed = (flat_groups[:, None] < 0) | (bank.k[None, :] == flat_groups[:, None])
    cost = torch.where(allowed, cost, torch.inf)
    penalty = torch.nan_to_num(lambda_prior * angle_distance(prior.reshape(-1, 1), bank.theta[None]), nan=0.0)
    return (cost + penalty).argmin(1), cost.argmin(1)


@pytest.mark.parametrize("shuffled", [False, True])
@pytest.mark.parametrize("lambda_prior", [0.0, 0.002, 100.0])
def test_per_angle_matching_equals_costing_every_row(shuffled: bool, lambda_prior: float) -> None:
    g = torch.Generator().manual_seed(1)
    n_groups, n_angles, per_angle, channels = 3, 12, 16, 32
    m = n_groups * n_angles * per_angle
    features = torch.randn(m, channels, generator=g) + 0.2
    k = torch.arange(n_groups).repeat_interleave(n_angles * per_angle)
    theta = (torch.arange(n_angles) * 30.0).repeat_interleave(per_angle).repeat(n_groups)
    order = torch.randperm(m, generator=g) if shuffled else torch.arange(m)
    bank = TextureBank(
        features[order], k[order], theta[order], (1.0, 0.8, 0.6), tuple(float(a) for a in range(0, 360, 30)), 4, "test"
    )
    feats = torch.randn(channels, 9, 11, generator=g) + 0.2
    prior = torch.rand(9, 11, generator=g) * 360.0
    prior[0] = math.nan
    groups = torch.randint(-1, n_groups, (9, 11), generator=g)
    match = match_with_prior(feats, bank, prior, lambda_prior, groups)
    best, free = brute_force_match(feats, bank, prior, lambda_prior, groups)
    assert torch.equal(match.indices.reshape(-1), best)
    assert torch.equal(match.free_angles.reshape(-1), bank.theta[free])


def test_matching_only_the_asked_cells_gives_them_the_same_targets() -> None:
    g = torch.Generator().manual_seed(2)
    bank = TextureBank(
        torch.randn(48, 8, generator=g),
        torch.zeros(48, dtype=torch.long),
        (torch.arange(4) * 90.0).repeat_interleave(12),
        (1.0,),
        (0.0, 90.0, 180.0, 270.0),
        2,
        "t",
    )
    feats = torch.randn(8, 5, 6, generator=g)
    prior = torch.rand(5, 6, generator=g) * 360.0
    cells = torch.rand(5, 6, generator=g) > 0.5
    everything = match_with_prior(feats, bank, prior, 0.01)
    some = match_with_prior(feats, bank, prior, 0.01, cells=cells)
    assert torch.equal(some.indices[cells], everything.indices[cells])
    assert torch.equal(some.angles[cells], everything.angles[cells])


def wall_scene() -> GaussianScene:
    """An opaque flat wall of Gaussians in the z = 0 plane and one small Gaussian just behind it."""
    side = torch.linspace(-1.0, 1.0, 21)
    yy, xx = torch.meshgrid(side, side, indexing="ij")
    wall = torch.stack([xx.reshape(-1), yy.reshape(-1), torch.zeros(xx.numel())], dim=1)
    means = torch.cat([wall, torch.tensor([[0.0, 0.0, 0.5]])])
    n = len(means)
    scales = torch.full((n, 3), 0.08)
    scales[:-1, 2] = 0.005
    return GaussianScene.from_activated(means, scales, torch.full((n,), 0.99), torch.full((n, 3), 0.5))


def test_contributions_are_tiny_behind_an_opaque_wall_and_large_in_front() -> None:
    from gt2gs_blender.core.cameras.camera import Camera

    scene = wall_scene()
    viewmat = np.eye(4)
    viewmat[2, 3] = 3.0  # camera at z = -3 looking along +z: the wall at z = 0 hides the Gaussian at z = 0.5
    camera = Camera(world_to_cam=viewmat, fx=60.0, fy=60.0, cx=32.0, cy=32.0, width=64, height=64)
    weight = contributions(scene, [camera])
    assert float(weight[-1]) < 0.1 and float(weight[:-1].max()) > 1.0
    hidden = hidden_gaussians(scene, [camera], 0.1)
    assert hidden is not None and bool(hidden[-1])


def faint_scene() -> tuple[GaussianScene, torch.Tensor]:
    """The blob scene with every 7th Gaussian made too faint to draw (alpha < 1/255 everywhere)."""
    scene = blob_scene()
    faint = torch.zeros(len(scene), dtype=torch.bool)
    faint[::7] = True
    logits = torch.where(faint, torch.full_like(scene.opacity_logits, -12.0), scene.opacity_logits)
    return replace(scene, opacity_logits=logits), faint


def test_hidden_gaussians_come_back_unchanged_in_place_and_are_never_rendered(tmp_path, monkeypatch) -> None:
    scene, faint = faint_scene()
    sizes: list[int] = []
    real_render = stylise_module.render
    monkeypatch.setattr(stylise_module, "render", lambda s, *a, **k: sizes.append(len(s)) or real_render(s, *a, **k))
    config = tiny(cache_dir=str(tmp_path), gpb=True, correct_steps=3, rounds=1)
    result = transfer(scene, stripes(), None, config)
    hidden = result.report["skips"]["hidden"]
    assert hidden is not None and hidden >= int(faint.sum())
    assert sizes and max(sizes) == len(scene) - hidden  # the styliser never drew a hidden Gaussian
    out, start = result.scene, scene.with_sh_degree(0)
    assert len(out) == len(scene)
    for name, tensor in start.tensors().items():
        assert torch.equal(out.tensors()[name][faint], tensor[faint]), name  # bit-identical, same index
    assert not torch.equal(out.sh_dc[~faint], start.sh_dc[~faint])  # the visible ones were restyled
    assert np.array_equal(out.extras["confidence"], scene.extras["confidence"])


def test_skipping_hidden_gaussians_changes_nothing_visible(tmp_path) -> None:
    """Gaussians that draw nothing get no gradient: skipping them leaves the drawn ones' result equal."""
    scene, _ = faint_scene()
    config = tiny(cache_dir=str(tmp_path), stylise_steps=3, hidden_threshold=0.0)
    on = transfer(scene, stripes(), None, config)
    off = transfer(scene, stripes(), None, replace(config, skip_hidden=False))
    hidden = torch.zeros(len(scene), dtype=torch.bool)
    hidden[:] = contributions(scene, auto_views(scene, 3, width=48, height=48)) <= 0.0
    assert on.report["skips"]["hidden"] == int(hidden.sum()) and off.report["skips"]["hidden"] is None
    torch.testing.assert_close(on.scene.sh_dc[~hidden], off.scene.sh_dc[~hidden], atol=1e-4, rtol=0)


def test_hidden_gaussians_in_a_region_keep_the_region_layout(tmp_path) -> None:
    scene, faint = faint_scene()
    region = torch.zeros(len(scene), dtype=torch.bool)
    region[::2] = True
    config = tiny(cache_dir=str(tmp_path), densify=True, densify_every=2, densify_grad_threshold=0.0)
    result = transfer(scene, stripes(), None, config, region=region)
    out, outside = result.scene, int((~region).sum())
    for name, tensor in scene.subset(~region).tensors().items():
        assert torch.equal(out.tensors()[name][:outside], tensor), name
    cameras = fit_cameras(scene.subset(region), None, config.resolution, config.n_views)
    both = region & (contributions(scene, cameras) <= config.hidden_threshold)
    assert result.report["skips"]["hidden"] >= int(faint.sum()) and bool(both.any())
    skipped = out.subset(slice(outside, outside + int(both.sum())))
    assert torch.equal(skipped.means, scene.means[both]) and skipped.sh_rest.abs().max() == 0
