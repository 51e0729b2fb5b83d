"""Renders from recorded compositing weights against the float64 reference and the rasterizer they replace."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from gt2gs_blender.core.cameras.camera import Camera
from gt2gs_blender.core.render import available_backends, fix_geometry, render
from gt2gs_blender.core.render.backends import KERNEL_BACKENDS
from gt2gs_blender.core.scene.gaussians import GaussianScene

from .reference import render_reference
from .test_rasterizer import random_gaussians, two_cameras

KERNELS = [b for b in available_backends("cpu") if b in KERNEL_BACKENDS]
"""The kernel backends (C++, numba) that record weights here; every test runs on each."""
pytestmark = pytest.mark.skipif(not KERNELS, reason="needs a CPU kernel (C++ or numba)")


def scene_of(n: int, sh_degree: int, seed: int = 0) -> GaussianScene:
    """A random scene (the rasterizer tests' Gaussians) with SH colours up to ``sh_degree``."""
    means, quats, scales, opacities, sh = random_gaussians(n, sh_degree, seed=seed)
    opacities = opacities.clamp(max=0.995)
    return GaussianScene(
        means=means,
        quats=quats,
        log_scales=scales.log(),
        opacity_logits=torch.logit(opacities),
        sh_dc=sh[:, 0].clone(),
        sh_rest=sh[:, 1:].clone(),
    )


def cameras(width: int = 61, height: int = 47) -> list[Camera]:
    viewmats, ks = two_cameras(width, height)
    return [
        Camera(v.double().numpy(), float(k[0, 0]), float(k[1, 1]), float(k[0, 2]), float(k[1, 2]), width, height)
        for v, k in zip(viewmats, ks)
    ]


@pytest.mark.parametrize("backend", KERNELS)
def test_recorded_weights_are_the_reference_renders_weights(backend):
    """Rendering N one-hot colour channels with the float64 reference gives every Gaussian's weight at
    every pixel: the recorded weights must be those (unambiguous pixels)."""
    scene = scene_of(60, 0)
    cams = cameras()
    fixed = fix_geometry(scene, cams, backend=backend)
    n, width, height = len(scene), cams[0].width, cams[0].height
    gauss = fixed.footprints.gauss_ids[fixed.entries.long()]
    rows = torch.repeat_interleave(torch.arange(fixed.offsets.numel() - 1), fixed.offsets.diff())
    dense = torch.zeros(len(cams) * height * width, n, dtype=torch.float64)
    dense.index_put_((rows, gauss), fixed.weights.double(), accumulate=True)
    dense = dense.reshape(len(cams), height, width, n).numpy()
    eye = np.eye(n)
    for b, cam in enumerate(cams):
        ref = render_reference(
            scene.means.numpy(),
            scene.quats.numpy(),
            scene.scales.numpy(),
            scene.opacities.numpy(),
            eye,
            cam.world_to_cam,
            cam.K,
            width,
            height,
        )
        ok = ~ref.ambiguous
        assert ok.mean() > 0.97
        assert np.abs(dense[b] - ref.color)[ok].max() < 1e-5
        assert np.abs(fixed.alphas[b].double().numpy() - ref.alpha)[ok].max() < 1e-5
    assert (fixed.weights > 0).all()


@pytest.mark.parametrize("backend", KERNELS)
@pytest.mark.parametrize("sh_degree", [0, 1, 3])
def test_fixed_render_and_colour_gradients_equal_the_rasterizers(sh_degree, backend):
    scene = scene_of(400, sh_degree, seed=3)
    cams = cameras()
    background = torch.tensor([0.2, 0.5, 0.9])
    probe = torch.randn(len(cams), cams[0].height, cams[0].width, 3, generator=torch.Generator().manual_seed(1))

    def colour_grads(render_fn):
        scene.sh_dc.requires_grad_(True)
        scene.sh_rest.requires_grad_(True)
        out = render_fn()
        (out.colors * probe).sum().backward()
        grads = scene.sh_dc.grad.clone(), scene.sh_rest.grad.clone()
        scene.sh_dc.grad = scene.sh_rest.grad = None
        return out, grads

    full, want = colour_grads(lambda: render(scene, cams, background=background, render_depth=False, backend=backend))
    fixed = fix_geometry(scene, cams, backend=backend)
    got_out, got = colour_grads(lambda: fixed.render(scene, background=background))
    torch.testing.assert_close(got_out.colors, full.colors, atol=1e-6, rtol=0)
    assert torch.equal(got_out.alphas, full.alphas)
    for g, w in zip(got, want):
        torch.testing.assert_close(g, w, atol=1e-5, rtol=1e-5)
    assert torch.equal(got_out.footprints.gauss_ids, full.footprints.gauss_ids)


@pytest.mark.parametrize("backend", KERNELS)
def test_fixed_render_follows_new_colours_and_refuses_another_scene(backend):
    scene = scene_of(200, 0, seed=5)
    cams = cameras()
    fixed = fix_geometry(scene, cams, backend=backend)
    with torch.no_grad():
        scene.sh_dc.mul_(-0.5).add_(0.3)
    torch.testing.assert_close(
        fixed.render(scene).colors, render(scene, cams, render_depth=False, backend=backend).colors, atol=1e-6, rtol=0
    )
    with pytest.raises(ValueError, match="fixed geometry of 200 Gaussians"):
        fixed.render(scene_of(201, 0))


@pytest.mark.parametrize("backend", KERNELS)
def test_no_fixed_geometry_where_only_a_full_render_can_draw(backend):
    scene = scene_of(50, 0)
    assert fix_geometry(scene, cameras(), backend="torch") is None
    assert fix_geometry(scene_of(50, 0).to(dtype=torch.float64), cameras(), backend=backend) is None
