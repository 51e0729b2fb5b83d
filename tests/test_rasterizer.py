"""Every rasterizer backend against the float64 dense reference, finite differences and analytic cases."""

from __future__ import annotations

import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from gt2gs_blender.core.cameras.camera import Camera
from gt2gs_blender.core.cameras.generate import auto_views
from gt2gs_blender.core.errors import GT2GSError
from gt2gs_blender.core.render import available_backends, gsplat_backend, numba_backend, rasterization, render
from gt2gs_blender.core.scene.gaussians import GaussianScene, quats_to_rotmats
from gt2gs_blender.core.scene.ply import read_ply

from .reference import frustum_clamp, render_reference, support_radius

BACKENDS = available_backends("cpu")
ROOT = Path(__file__).resolve().parents[1]


def look_camera(yaw: float, pitch: float, dist: float, width: int, height: int, focal: float):
    """A camera at distance ``dist`` from the origin looking at it (OpenCV frame): viewmat, K."""
    fwd = np.array([math.sin(yaw) * math.cos(pitch), math.sin(pitch), math.cos(yaw) * math.cos(pitch)])
    center = -dist * fwd
    right = np.cross([0.0, -1.0, 0.0], fwd)
    right /= np.linalg.norm(right)
    down = np.cross(fwd, right)
    rot = np.stack([right, down, fwd])
    viewmat = np.eye(4)
    viewmat[:3, :3] = rot
    viewmat[:3, 3] = -rot @ center
    k = np.array([[focal, 0, width / 2.0], [0, focal * 1.05, height / 2.0], [0, 0, 1]])
    return torch.tensor(viewmat, dtype=torch.float32), torch.tensor(k, dtype=torch.float32)


def random_gaussians(n: int, sh_degree: int | None, *, spread=1.0, log_scale=-3.0, aniso=1.0, seed=0):
    g = torch.Generator().manual_seed(seed)
    means = (torch.rand(n, 3, generator=g) * 2 - 1) * spread
    quats = torch.randn(n, 4, generator=g)
    scales = torch.exp(log_scale + 0.6 * torch.randn(n, 3, generator=g) + aniso * torch.rand(n, 3, generator=g))
    opacities = torch.rand(n, generator=g) * 0.98 + 0.02
    opacities[: n // 10] = 1.0  # exercise the 0.99 clamp
    if sh_degree is None:
        colors = torch.rand(n, 3, generator=g)
    else:
        colors = torch.randn(n, (sh_degree + 1) ** 2, 3, generator=g) * 0.4
    return means, quats, scales, opacities, colors


def two_cameras(width=61, height=47):
    v1, k1 = look_camera(0.2, 0.1, 3.0, width, height, 60.0)
    v2, k2 = look_camera(-0.7, -0.3, 2.5, width, height, 45.0)
    return torch.stack([v1, v2]), torch.stack([k1, k2])


def compare_to_reference(gaussians, viewmats, ks, width, height, backend, sh_degree, tol=1e-4):
    out = rasterization(*gaussians, viewmats, ks, width, height, sh_degree=sh_degree, backend=backend)
    assert out.backend == backend
    for b in range(viewmats.shape[0]):
        ref = render_reference(
            *(t.numpy() for t in gaussians), viewmats[b].numpy(), ks[b].numpy(), width, height, sh_degree=sh_degree
        )
        ok = ~ref.ambiguous
        assert ok.mean() > 0.97, "too many threshold-ambiguous pixels for a meaningful comparison"
        color = out.colors[b].double().numpy()
        assert np.abs(color - ref.color)[ok].max() <= tol
        assert np.abs(out.alphas[b].double().numpy() - ref.alpha)[ok].max() <= tol
        depth_scale = max(1.0, float((ref.depth / np.maximum(ref.alpha, 1e-3)).max()))  # colour tol per unit z
        assert np.abs(out.depths[b].double().numpy() - ref.depth)[ok].max() <= tol * depth_scale
    return out


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("sh_degree", [None, 0, 1, 2, 3])
def test_matches_reference_random_scenes(backend, sh_degree):
    gaussians = random_gaussians(300, sh_degree, seed=sh_degree or 7)
    viewmats, ks = two_cameras()
    out = compare_to_reference(gaussians, viewmats, ks, 61, 47, backend, sh_degree)
    assert out.alphas.max() > 0.5  # the scene is really visible


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("channels", [1, 6])
def test_matches_reference_any_channel_count(backend, channels):
    """Colour channel counts other than RGB (1 + depth, 6 + depth: the kernels' run-time channel path)."""
    means, quats, scales, opacities, _ = random_gaussians(300, None, seed=11)
    colors = torch.rand(300, channels, generator=torch.Generator().manual_seed(1))
    viewmats, ks = two_cameras()
    out = compare_to_reference((means, quats, scales, opacities, colors), viewmats, ks, 61, 47, backend, None)
    assert out.colors.shape[-1] == channels and out.alphas.max() > 0.5


@pytest.mark.parametrize("backend", BACKENDS)
def test_matches_reference_extreme_gaussians(backend):
    """Tiny, huge and 1000:1 anisotropic Gaussians, and ones near, on and behind the near plane."""
    viewmats, ks = two_cameras(40, 32)
    means, quats, scales, opacities, colors = random_gaussians(60, None, seed=3)
    scales[0:10] = 1e-5  # far below a pixel: the dilation dominates
    scales[10:14] = 3.0  # larger than the view
    scales[14:24, 0] = scales[14:24, 1] * 1000.0  # needles
    cam_center = -viewmats[0, :3, :3].T @ viewmats[0, :3, 3]
    fwd = viewmats[0, 2, :3]
    for i, z in enumerate([0.02, 0.0102, 0.0098, -0.5, 0.3]):  # near plane is 0.01
        means[24 + i] = cam_center + z * fwd
        scales[24 + i] = 0.01
    compare_to_reference((means, quats, scales, opacities, colors), viewmats, ks, 40, 32, backend, None)


def test_reference_frustum_clamp_is_the_published_rule():
    """The oracle's clamp: +-1.3 tan(fov/2) for a centred principal point (INRIA 3DGS), shifted with an
    off-centre one as gsplat's persp_proj does; points inside pass unchanged."""
    width, height, fx, fy = 64, 48, 40.0, 50.0
    tan_x, tan_y = 0.5 * width / fx, 0.5 * height / fy
    centred = np.array([[fx, 0, width / 2], [0, fy, height / 2], [0, 0, 1]])
    assert np.allclose(frustum_clamp(10.0, -10.0, centred, width, height), [1.3 * tan_x, -1.3 * tan_y])
    assert np.allclose(frustum_clamp(0.2, -0.3, centred, width, height), [0.2, -0.3])
    shifted = np.array([[fx, 0, 16.0], [0, fy, 12.0], [0, 0, 1]])
    assert np.allclose(
        frustum_clamp(10.0, 10.0, shifted, width, height),
        [(width - 16.0) / fx + 0.3 * tan_x, (height - 12.0) / fy + 0.3 * tan_y],
    )
    assert np.allclose(
        frustum_clamp(-10.0, -10.0, shifted, width, height), [-(16.0 / fx + 0.3 * tan_x), -(12.0 / fy + 0.3 * tan_y)]
    )


@pytest.mark.parametrize("backend", BACKENDS)
def test_single_gaussian_footprint_is_analytic(backend):
    """An isotropic Gaussian facing the camera: alpha = o * exp(-r^2 / (2 s^2)) with s^2 = (f s3 / z)^2 + 0.3,
    exactly zero beyond the radius where alpha = 1/255."""
    width = height = 48
    focal, z, s3, o = 40.0, 2.0, 0.1, 0.8
    viewmat = torch.eye(4)[None]
    k = torch.tensor([[[focal, 0, 24.0], [0, focal, 24.0], [0, 0, 1]]])
    means = torch.tensor([[0.0, 0.0, z]])
    out = rasterization(
        means,
        torch.tensor([[1.0, 0, 0, 0]]),
        torch.full((1, 3), s3),
        torch.tensor([o]),
        torch.ones(1, 3),
        viewmat,
        k,
        width,
        height,
        backend=backend,
    )
    sigma2 = (focal * s3 / z) ** 2 + 0.3
    ys, xs = np.mgrid[0:height, 0:width] + 0.5
    r2 = (xs - 24.0) ** 2 + (ys - 24.0) ** 2
    expected = np.minimum(0.99, o * np.exp(-r2 / (2 * sigma2)))
    expected[expected < 1 / 255] = 0.0
    alpha = out.alphas[0].numpy()
    assert np.abs(alpha - expected).max() < 1e-5
    assert np.abs(out.depths[0].numpy() - z * expected).max() < 1e-5
    r = support_radius(o, math.sqrt(sigma2))
    assert (alpha[r2 > (r + 0.01) ** 2] == 0).all() and (alpha[r2 < (r - 0.01) ** 2] > 0).all()


def tiny_scene_f64(sh_degree):
    g = torch.Generator().manual_seed(11)
    n = 5
    means = torch.rand(n, 3, generator=g, dtype=torch.float64) * 0.6 - 0.3
    quats = torch.randn(n, 4, generator=g, dtype=torch.float64)
    scales = torch.rand(n, 3, generator=g, dtype=torch.float64) * 0.1 + 0.05
    opacities = torch.rand(n, generator=g, dtype=torch.float64) * 0.5 + 0.3
    k = 1 if sh_degree is None else (sh_degree + 1) ** 2
    colors = (
        torch.rand(n, 3, generator=g, dtype=torch.float64)
        if sh_degree is None
        else torch.randn(n, k, 3, generator=g, dtype=torch.float64) * 0.3
    )
    viewmats, ks = two_cameras(14, 12)
    ks = ks.double()
    ks[:, :2] *= 0.35
    return [means, quats, scales, opacities, colors], viewmats.double(), ks


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("sh_degree", [None, 2])
def test_gradcheck_all_gaussian_parameters(backend, sh_degree):
    params, viewmats, ks = tiny_scene_f64(sh_degree)
    weights = torch.rand(2, 12, 14, 5, dtype=torch.float64)

    def f(*p):
        out = rasterization(*p, viewmats, ks, 14, 12, sh_degree=sh_degree, backend=backend)
        return (
            (out.colors * weights[..., :3]).sum()
            + (out.depths * weights[..., 3]).sum()
            + (out.alphas * weights[..., 4]).sum()
        )

    inputs = [p.clone().requires_grad_(True) for p in params]
    assert torch.autograd.gradcheck(f, inputs, eps=1e-6, atol=1e-5, rtol=1e-4)


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("sh_degree", [0, 3])
def test_colour_only_gradients_equal_the_full_backward(backend, sh_degree):
    """A step that trains only colours (and opacities), as the stylise phases on an object, gets the same
    gradients for them as a step that trains everything: the backward skips only what nothing trains."""
    gaussians = random_gaussians(400, sh_degree, seed=11)
    viewmats, ks = two_cameras(64, 48)
    weights = torch.rand(2, 48, 64, 3, generator=torch.Generator().manual_seed(2))

    def grads(trained: tuple[int, ...]) -> list[torch.Tensor | None]:
        inputs = [t.detach().clone().requires_grad_(k in trained) for k, t in enumerate(gaussians)]
        out = rasterization(*inputs, viewmats, ks, 64, 48, sh_degree=sh_degree, backend=backend)
        ((out.colors * weights).sum() + out.alphas.sum()).backward()
        return [t.grad for t in inputs]

    full = grads((0, 1, 2, 3, 4))  # means, quats, scales, opacities, SH
    for trained in ((3, 4), (4,)):
        partial = grads(trained)
        for k in range(5):
            assert torch.equal(partial[k], full[k]) if k in trained else partial[k] is None


@pytest.mark.parametrize("backend", BACKENDS)
def test_float32_gradients_match_float64(backend):
    """Gradient relative error of the float32 path against the float64 one (gradchecked above) <= 1e-3."""
    gaussians = random_gaussians(400, 3, seed=5)
    viewmats, ks = two_cameras(64, 48)
    weights = torch.rand(2, 48, 64, 3, dtype=torch.float64)
    grads = {}
    for dtype in (torch.float32, torch.float64):
        inputs = [t.detach().to(dtype).requires_grad_(True) for t in gaussians]
        out = rasterization(*inputs, viewmats.to(dtype), ks.to(dtype), 64, 48, sh_degree=3, backend=backend)
        ((out.colors * weights.to(dtype)).sum() + 0.1 * out.depths.sum()).backward()
        grads[dtype] = [t.grad.double() for t in inputs]
    for g32, g64 in zip(grads[torch.float32], grads[torch.float64]):
        assert (g32 - g64).norm() <= 1e-3 * g64.norm()


@pytest.mark.parametrize("loop_max", [0, 1000])
def test_torch_backend_small_chunks_match_reference(monkeypatch, loop_max):
    """Chunks of 2 entries (hundreds of pixels stopping at T < 1e-4 inside and across chunks), scanned
    with slice loops or with torch.cumprod/cumsum: reference images, and the default chunking's gradients."""
    from gt2gs_blender.core.render import torch_backend

    gaussians = random_gaussians(300, 3, seed=6, spread=0.5)
    viewmats, ks = two_cameras()
    weights = torch.rand(2, 47, 61, 3, generator=torch.Generator().manual_seed(1))

    def grads():
        inputs = [t.clone().requires_grad_(True) for t in gaussians]
        out = rasterization(*inputs, viewmats, ks, 61, 47, sh_degree=3, backend="torch")
        ((out.colors * weights).sum() + out.depths.sum() + out.alphas.sum()).backward()
        return [t.grad for t in inputs]

    expected = grads()
    monkeypatch.setattr(torch_backend, "CHUNK_MIN", 2)
    monkeypatch.setattr(torch_backend, "CHUNK_ELEMENTS", 1)
    monkeypatch.setattr(torch_backend, "LOOP_MAX", loop_max)
    assert torch_backend.chunk_size(1) == 2
    out = compare_to_reference(gaussians, viewmats, ks, 61, 47, "torch", 3)
    assert out.alphas.max() > 0.9998  # pixels really stop
    for got, want in zip(grads(), expected):
        assert (got - want).norm() <= 1e-5 * want.norm()


def test_backends_agree_with_each_other():
    if len(BACKENDS) < 2:
        pytest.skip(f"only {BACKENDS} available here")
    gaussians = random_gaussians(2000, 3, seed=9, spread=1.5)
    viewmats, ks = two_cameras(96, 80)
    outs = []
    for backend in BACKENDS:
        inputs = [t.clone().requires_grad_(True) for t in gaussians]
        out = rasterization(*inputs, viewmats, ks, 96, 80, sh_degree=3, backend=backend)
        (out.colors.square().sum() + out.alphas.sum()).backward()
        outs.append((out.colors.detach(), [t.grad for t in inputs]))
    c0, g0 = outs[-1]  # the portable torch backend, the others against it
    for c1, g1 in outs[:-1]:
        assert (c0 - c1).abs().max() < 1e-5
        for a, b in zip(g0, g1):
            assert (a - b).norm() <= 1e-4 * b.norm()


@pytest.mark.parametrize("backend", BACKENDS)
def test_background_and_empty_views(backend):
    gaussians = random_gaussians(50, None, seed=2)
    means = gaussians[0] + torch.tensor([0.0, 0.0, -100.0])  # everything behind the camera
    viewmats, ks = two_cameras(16, 16)
    inputs = [means.requires_grad_(True)] + [t.clone().requires_grad_(True) for t in gaussians[1:]]
    bg = torch.tensor([0.2, 0.4, 0.6])
    out = rasterization(*inputs, viewmats, ks, 16, 16, backgrounds=bg, backend=backend)
    assert torch.equal(out.alphas, torch.zeros(2, 16, 16))
    assert torch.allclose(out.colors, bg.expand(2, 16, 16, 3))
    out.colors.sum().backward()
    assert all(torch.count_nonzero(t.grad) == 0 for t in inputs)


@pytest.mark.parametrize("backend", BACKENDS)
def test_background_composites_over_transparency(backend):
    gaussians = random_gaussians(200, None, seed=4)
    viewmats, ks = two_cameras(32, 24)
    plain = rasterization(*gaussians, viewmats, ks, 32, 24, backend=backend)
    bg = torch.tensor([[1.0, 0.0, 0.5], [0.0, 1.0, 0.25]])
    over = rasterization(*gaussians, viewmats, ks, 32, 24, backgrounds=bg, backend=backend)
    expected = plain.colors + (1 - plain.alphas[..., None]) * bg[:, None, None, :]
    assert torch.allclose(over.colors, expected, atol=1e-6)


def test_quaternion_convention_is_w_first():
    """A 90-degree turn about z (w, x, y, z) = (cos 45, 0, 0, sin 45) maps x to y."""
    q = torch.tensor([[math.cos(math.pi / 4), 0.0, 0.0, math.sin(math.pi / 4)]])
    assert torch.allclose(quats_to_rotmats(q)[0] @ torch.tensor([1.0, 0, 0]), torch.tensor([0.0, 1, 0]), atol=1e-6)


@pytest.mark.skipif(not gsplat_backend.available(), reason="gsplat backend needs CUDA and the gsplat package")
def test_gsplat_matches_reference_on_cuda():
    gaussians = [t.cuda() for t in random_gaussians(300, 3, seed=8)]
    viewmats, ks = two_cameras()
    out = rasterization(*gaussians, viewmats.cuda(), ks.cuda(), 61, 47, sh_degree=3, backend="gsplat")
    for b in range(2):
        ref = render_reference(
            *(t.cpu().numpy() for t in gaussians), viewmats[b].numpy(), ks[b].numpy(), 61, 47, sh_degree=3
        )
        # gsplat cuts footprints at 3 sigma, not at alpha = 1/255: compare away from faint rims
        assert np.median(np.abs(out.colors[b].double().cpu().numpy() - ref.color)) < 1e-4


def footprint_gradients(backend: str, device: str) -> dict[int, tuple[torch.Tensor, torch.Tensor]]:
    """{camera * N + Gaussian: (2D mean, its gradient)} of a squared-error loss, as density control reads them."""
    gaussians = [t.to(device).requires_grad_() for t in random_gaussians(300, 3, seed=8)]
    viewmats, ks = (t.to(device) for t in two_cameras())
    target = torch.rand(2, 47, 61, 3, generator=torch.Generator().manual_seed(1)).to(device)
    out = rasterization(*gaussians, viewmats, ks, 61, 47, sh_degree=3, backend=backend, render_depth=False)
    assert out.backend == backend
    f = out.footprints
    f.means2d.retain_grad()
    ((out.colors - target) ** 2).sum().backward()
    keys = (f.cam_ids * 300 + f.gauss_ids).tolist()
    return dict(zip(keys, zip(f.means2d.detach().double().cpu(), f.means2d.grad.double().cpu())))


def assert_same_footprints(got: dict, want: dict, *, seen: float, means_tol: float, grad_rel: float) -> None:
    """Most pairs seen by both, at the same 2D means, with the same gradients there (relative norm)."""
    common = sorted(got.keys() & want.keys())
    assert len(common) >= seen * len(want) and len(common) >= seen * len(got)
    stacked = {name: [torch.stack([d[k][i] for k in common]) for i in (0, 1)] for name, d in (("g", got), ("w", want))}
    assert torch.allclose(stacked["g"][0], stacked["w"][0], atol=means_tol)
    g, w = stacked["g"][1], stacked["w"][1]
    assert torch.linalg.norm(g - w) <= grad_rel * torch.linalg.norm(w)


@pytest.mark.parametrize("backend", [b for b in BACKENDS if b != "torch"])
def test_a_render_past_the_kernels_pair_limit_is_one_error_saying_what_to_shrink(backend):
    """1,500 splats each covering every tile of one 10,000 px view: over 2^31 splat/tile pairs, counted before any
    is stored. The kernel's own words ("render fewer cameras at once") misled with a single camera."""
    n, side = 1500, 10000
    scene = GaussianScene.from_activated(
        means=torch.tensor([[0.0, 0.0, 3.0]]).repeat(n, 1),
        scales=torch.full((n, 3), 5.0),
        opacities=torch.full((n,), 0.9),
        colors=torch.rand(n, 3),
    )
    camera = Camera.from_cam_to_world(np.eye(3), [0.0, 0.0, 0.0], side / 2, side / 2, side / 2, side / 2, side, side)
    with pytest.raises(GT2GSError, match=r"too large for the rasterizer \(1 view of 10000x10000 px: over 2\^31"):
        render(scene, [camera], backend=backend)


@pytest.mark.parametrize("backend", [b for b in BACKENDS if b != "torch"])
def test_cpu_footprints_carry_the_torch_backends_gradients(backend):
    """Density control reads a compiled kernel's entries (C++ or numba) as the torch backend's: same pairs,
    means, gradients."""
    got, want = footprint_gradients(backend, "cpu"), footprint_gradients("torch", "cpu")
    assert_same_footprints(got, want, seen=0.99, means_tol=1e-4, grad_rel=1e-3)


@pytest.mark.skipif(not gsplat_backend.available(), reason="gsplat backend needs CUDA and the gsplat package")
def test_gsplat_footprints_carry_the_torch_backends_gradients_on_cuda():
    """gsplat renders packed, so density control reads its visible pairs and their 2D-mean gradients as the torch
    backend's (its 3-sigma footprint differs at faint rims, hence the tolerances)."""
    got, want = footprint_gradients("gsplat", "cuda"), footprint_gradients("torch", "cuda")
    assert_same_footprints(got, want, seen=0.9, means_tol=1e-3, grad_rel=0.1)


def test_render_real_scene_backends_agree(shared):
    """The shared donut through the scene-level API: every CPU backend gives the torch one's image and depth."""
    if len(BACKENDS) < 2:
        pytest.skip(f"only {BACKENDS} available here")
    scene = read_ply(shared / "data/scenes/donut/point_cloud.ply")
    cams = auto_views(scene, 2, width=96, height=96)
    outs = [render(scene, cams, background=(1.0, 1.0, 1.0), backend=b) for b in BACKENDS]
    assert outs[-1].alphas.mean() > 0.1
    for out in outs[:-1]:
        # float32 rounding may flip an alpha >= 1/255 decision: such a pixel differs by at most 1/255
        diff = (out.colors - outs[-1].colors).abs().amax(-1)
        assert diff.max() <= 1 / 255 and (diff > 1e-5).float().mean() < 1e-3
        assert ((out.depths - outs[-1].depths).abs() > 1e-4).float().mean() < 1e-3


def test_kernel_build_failure_falls_back_with_reason(tmp_path):
    """No usable compiler: the cpu backend is reported unavailable with a reason and auto picks the next one
    (numba where it is installed, else torch)."""
    code = (
        "import logging; logging.basicConfig(level=logging.WARNING)\n"
        "from gt2gs_blender.core.render import available_backends, cpu_backend\n"
        "print(available_backends('cpu')); print('reason:', cpu_backend.unavailable_reason())\n"
    )
    env = dict(os.environ, CXX=str(tmp_path / "no-such-compiler"), GT2GS_BUILD_DIR=str(tmp_path / "build"))
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=ROOT, timeout=300)
    assert proc.returncode == 0, proc.stderr
    usable = ["numba", "torch"] if numba_backend.installed() else ["torch"]
    assert str(usable) in proc.stdout and "reason: " in proc.stdout and "reason: None" not in proc.stdout
    assert "fast CPU rasterizer unavailable" in proc.stderr


@pytest.mark.parametrize("backend", BACKENDS)
def test_gradients_are_reproducible(backend):
    """Same inputs, same gradients, bit for bit (runs must be deterministic with a seed)."""
    gaussians = random_gaussians(3000, 3, seed=12, spread=1.5)
    viewmats, ks = two_cameras(96, 80)
    grads = []
    for _ in range(3):
        inputs = [t.clone().requires_grad_(True) for t in gaussians]
        out = rasterization(*inputs, viewmats, ks, 96, 80, sh_degree=3, backend=backend)
        (out.colors.square().sum() + out.alphas.sum()).backward()
        grads.append([t.grad for t in inputs])
    for other in grads[1:]:
        assert all(torch.equal(a, b) for a, b in zip(grads[0], other))
