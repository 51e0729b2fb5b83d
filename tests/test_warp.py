"""Reprojection warp against an analytic oracle: a textured plane seen by two cameras, whose
dst -> src mapping is the plane homography H = K_s (R + t n^T / d) K_d^-1."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
import torch

from gt2gs_blender.core.cameras.camera import Camera
from gt2gs_blender.core.cameras.warp import backproject, expected_depth, pixel_centres, reproject, warp_image

W, H = 64, 48
NORMAL, OFFSET = np.array([0.1, -0.05, 1.0]) / np.linalg.norm([0.1, -0.05, 1.0]), 4.0  # world plane n.X = d


def rotation(ax: float, ay: float) -> np.ndarray:
    """Rotation about x by ``ax`` then y by ``ay`` (radians)."""
    cx, sx, cy, sy = math.cos(ax), math.sin(ax), math.cos(ay), math.sin(ay)
    return np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]]) @ np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])


def camera(ax: float, ay: float, centre, cx: float = 31.3, cy: float = 24.6) -> Camera:
    return Camera.from_cam_to_world(rotation(ax, ay), centre, 58.0, 61.0, cx, cy, W, H)


SRC = camera(0.0, 0.0, [0.0, 0.0, 0.0])
DST = camera(0.06, -0.12, [0.9, -0.3, 0.4], cx=32.8, cy=23.1)


def plane_depth(cam: Camera) -> torch.Tensor:
    """Exact camera depth of the plane at every pixel centre (ray-plane intersection)."""
    uv = pixel_centres(cam).numpy()
    rays_cam = np.concatenate(
        [(uv[..., :1] - cam.cx) / cam.fx, (uv[..., 1:] - cam.cy) / cam.fy, np.ones((H, W, 1))], -1
    )
    rays_world = rays_cam @ cam.world_to_cam[:3, :3]
    return torch.from_numpy((OFFSET - NORMAL @ cam.center) / (rays_world @ NORMAL))


def pattern(points: torch.Tensor) -> torch.Tensor:
    """A smooth RGB texture painted on the plane, a function of world position."""
    x, y = points[..., 0], points[..., 1]
    return torch.stack(
        [0.5 + 0.4 * torch.sin(2.5 * x), 0.5 + 0.4 * torch.cos(2.0 * y), 0.5 + 0.3 * torch.sin(x + y)], -1
    )


def homography_dst_to_src() -> np.ndarray:
    """The plane homography from the destination to the source image."""
    r_d, t_d = DST.world_to_cam[:3, :3], DST.world_to_cam[:3, 3]
    r_s, t_s = SRC.world_to_cam[:3, :3], SRC.world_to_cam[:3, 3]
    n_c = r_d @ NORMAL
    d_c = OFFSET + n_c @ t_d  # the plane in the destination camera frame: n_c . X = d_c
    r = r_s @ r_d.T
    t = t_s - r @ t_d
    return SRC.K @ (r + np.outer(t, n_c) / d_c) @ np.linalg.inv(DST.K)


def homography_uv() -> np.ndarray:
    centres = pixel_centres(DST).numpy().reshape(-1, 1, 2)
    return cv2.perspectiveTransform(centres, homography_dst_to_src()).reshape(H, W, 2)


def inside(uv: np.ndarray, margin: float) -> np.ndarray:
    return (uv[..., 0] >= margin) & (uv[..., 0] <= W - margin) & (uv[..., 1] >= margin) & (uv[..., 1] <= H - margin)


def in_box(uv: np.ndarray, margin: float) -> np.ndarray:
    """Source coordinates inside the occluder box (columns 20-32, rows 10-20) grown by ``margin``."""
    u, v = uv[..., 0], uv[..., 1]
    return (u > 20 - margin) & (u < 32 + margin) & (v > 10 - margin) & (v < 20 + margin)


def warp_plane(**kwargs):
    src_depth = kwargs.pop("src_depth", plane_depth(SRC))
    image = pattern(backproject(plane_depth(SRC), SRC))
    return warp_image(image, src_depth, SRC, DST, plane_depth(DST), **kwargs)


def test_backproject_reproject_round_trip():
    depth = plane_depth(DST)
    uv, z = reproject(backproject(depth, DST), DST)
    torch.testing.assert_close(uv, pixel_centres(DST), atol=1e-9, rtol=0)
    torch.testing.assert_close(z, depth, atol=1e-9, rtol=0)
    on_plane = backproject(depth, DST) @ torch.from_numpy(NORMAL)
    assert torch.allclose(on_plane, torch.full((H, W), OFFSET, dtype=torch.float64))


def test_flow_is_the_plane_homography():
    warp = warp_plane()
    expected = homography_uv()
    assert np.abs(warp.src_uv.numpy() - expected).max() < 1e-3
    ok = inside(expected, 1.0)
    assert 0.3 < ok.mean() < 0.95  # part of the destination view leaves the source image
    assert warp.valid.numpy()[ok].all() and not warp.valid.numpy()[~inside(expected, 0.0)].any()


def test_warped_image_shows_the_same_surface():
    warp = warp_plane()
    truth = pattern(backproject(plane_depth(DST), DST))
    error = (warp.image - truth).abs().amax(-1)
    centres_inside = torch.from_numpy(inside(homography_uv(), 0.5)) & warp.valid
    assert error[centres_inside].max() < 3e-3  # bilinear resampling of a smooth pattern
    assert error[warp.valid].max() < 0.04  # within half a pixel of the edge the edge pixel is used
    assert (warp.image[~warp.valid] == 0).all()


def test_nearer_surface_in_source_occludes():
    src_depth = plane_depth(SRC).clone()
    src_depth[10:20, 20:32] = 2.0  # an object in front of the plane, seen only by the source
    warp = warp_plane(src_depth=src_depth)
    uv = homography_uv()
    hidden = in_box(uv, -1.0)
    assert hidden.sum() > 50 and not warp.valid.numpy()[hidden].any()
    assert warp.valid.numpy()[inside(uv, 1.0) & ~in_box(uv, 1.0)].all()


def test_alpha_masks_and_expected_depth():
    src_alpha, dst_alpha = torch.ones(H, W), torch.ones(H, W)
    src_alpha[:, :16] = 0.2
    dst_alpha[30:, :] = 0.0
    warp = warp_plane(src_alpha=src_alpha, dst_alpha=dst_alpha)
    uv = homography_uv()
    assert not warp.valid.numpy()[30:].any() and not warp.valid.numpy()[uv[..., 0] < 15.5].any()
    assert warp.valid.numpy()[:30][inside(uv[:30], 1.0) & (uv[:30, :, 0] > 16.5)].all()
    depth = torch.tensor([[2.0, 0.3], [0.8, 0.0]])
    alpha = torch.tensor([[1.0, 0.4], [0.5, 0.0]])
    torch.testing.assert_close(expected_depth(depth, alpha), torch.tensor([[2.0, 0.0], [1.6, 0.0]]))


def test_nearest_mode_keeps_labels():
    labels = torch.arange(W * H, dtype=torch.float64).reshape(H, W, 1)
    warp = warp_image(labels, plane_depth(SRC), SRC, DST, plane_depth(DST), mode="nearest")
    uv = torch.from_numpy(homography_uv())
    expected = (uv[..., 1].floor() * W + uv[..., 0].floor())[..., None]
    assert torch.equal(warp.image[warp.valid], expected[warp.valid])


def test_size_mismatch_is_rejected():
    with pytest.raises(ValueError, match="source image"):
        warp_image(torch.zeros(H + 1, W, 3), plane_depth(SRC), SRC, DST, plane_depth(DST))
