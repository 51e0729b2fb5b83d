"""Texture Softness (``core/transfer/grain.py``): a periodic Gaussian blur of the texture photo, checked against a
spatial blur of the tiled photo (the independent oracle), shift-equivariance (no seam) and its limits."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from gt2gs_blender.core.transfer.grain import SPATIAL_MAX_SIGMA, periodic_blur, softened


def _photo(height: int = 64, width: int = 48) -> np.ndarray:
    """A float32 RGB texture with noise and a jump at its borders (a gradient that does not wrap around)."""
    y, x = np.mgrid[0:height, 0:width].astype(np.float32)
    noise = np.random.default_rng(0).random((height, width), dtype=np.float32)
    return np.stack([x / (width - 1), y / (height - 1), noise], axis=-1)


def test_softness_zero_returns_the_texture_unchanged():
    texture = _photo()
    assert softened(texture, 0.0) is texture


@pytest.mark.parametrize("share", [0.05, 0.2])  # 3.2 px and 12.8 px of a 64 px texture
def test_softened_texture_is_the_tiled_photo_blurred(share):
    """The centre of a 3 x 3 tiling blurred in space by OpenCV: the same blur, with the photo's neighbours in place
    of its borders."""
    texture = _photo()
    tiled = cv2.GaussianBlur(np.tile(texture, (3, 3, 1)), (0, 0), share * 64)
    soft = softened(texture, share)
    assert soft.dtype == np.float32 and soft.shape == texture.shape
    np.testing.assert_allclose(soft, tiled[64:128, 48:96], atol=2e-4)


def test_softened_texture_has_no_seam_at_a_narrow_blur():
    """Shifting the photo shifts its softened copy exactly: the borders are blurred like any other place (0.01 of
    the height, 0.64 px, the default's width on a small photo)."""
    texture = _photo()
    shifted = np.roll(texture, (17, 29), axis=(0, 1))
    np.testing.assert_allclose(
        softened(shifted, 0.01), np.roll(softened(texture, 0.01), (17, 29), axis=(0, 1)), atol=1e-5
    )
    assert np.abs(softened(texture, 0.01) - texture).max() > 0.05  # the noise channel did soften


def test_a_blur_wider_than_the_photo_leaves_its_mean_colour_and_every_blur_keeps_the_mean():
    texture = _photo()
    np.testing.assert_allclose(softened(texture, 1.5), np.broadcast_to(texture.mean((0, 1)), texture.shape), atol=1e-4)
    np.testing.assert_allclose(softened(texture, 0.05).mean((0, 1)), texture.mean((0, 1)), atol=1e-5)


@pytest.mark.parametrize("sigma", [2.0, SPATIAL_MAX_SIGMA, 2 * SPATIAL_MAX_SIGMA])  # the kernel, its limit, Fourier
def test_periodic_blur_is_the_tiled_photo_blurred_and_has_no_seam(sigma):
    """The layout's pyramid blur (in pixels) equals OpenCV's blur of the photo tiled 5 x 5 at its centre, and
    commutes with a shift; a mirrored blur (OpenCV's default border) does not."""
    texture = _photo()
    tiled = cv2.GaussianBlur(np.tile(texture, (5, 5, 1)), (0, 0), sigma)  # 4 sigma fits in two tiles
    blurred = periodic_blur(texture, sigma)
    assert blurred.dtype == np.float32 and blurred.shape == texture.shape
    np.testing.assert_allclose(blurred, tiled[128:192, 96:144], atol=2e-4)
    rolled = np.roll(texture, (17, 29), axis=(0, 1))
    np.testing.assert_allclose(periodic_blur(rolled, sigma), np.roll(blurred, (17, 29), axis=(0, 1)), atol=2e-4)
    mirrored = cv2.GaussianBlur(texture, (0, 0), sigma)
    assert np.abs(mirrored - blurred).max() > 0.05


def test_periodic_blur_of_a_photo_smaller_than_its_kernel():
    """A kernel wider than the photo wraps around it several times: an 8 px photo at 6 px is nearly its mean."""
    texture = _photo(8, 8)
    blurred = periodic_blur(texture, 6.0)
    np.testing.assert_allclose(blurred, np.broadcast_to(texture.mean((0, 1)), texture.shape), atol=1e-3)
