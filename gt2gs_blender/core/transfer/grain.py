"""Texture Softness: the texture photo's finest grain softened before a run lays it on and matches it.

A photo's speckle, finer than splats can draw at the working resolution, only crosses the capture's plain stretches
under the texture (SSIM to the original counts every such line against the scene), while planks, bricks and cells
are coarser. The blur is a Gaussian of a share of one repeat (the texture's height), applied as the layout and the
bank read the texture: tiled, so it is periodic (no seam at a repeat's edge). In Fourier space that is exact for any
width, from a fraction of a pixel to more than the image, and its cost does not grow with the width (a 4k photo in
under a second on 2 cores, where a spatial kernel 4 sigma wide took seconds at 0.01 and minutes at 0.1).
The layout's prefilter pyramid blurs the same periodic way (``periodic_blur``), so a splat's colour near a repeat's
edge averages the next repeat's texels, not a mirror image of its own.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import torch

SPATIAL_MAX_SIGMA = 8.0
"""``periodic_blur`` runs blurs up to this many pixels as OpenCV's kernel over the image padded by wrapping (a
few hundredths of a second on a 4k photo) and wider ones in Fourier space (whose cost does not grow with the
width: a 64 px kernel took seconds on a 4k photo); the two agree within 1e-5 from 2 px up."""


def softened(image: np.ndarray, share: float) -> np.ndarray:
    """``image`` (H, W, 3) blurred by a Gaussian of ``share`` of its height, read as periodic so it still tiles
    seamlessly; 0 returns it unchanged."""
    if share <= 0.0:
        return image
    height, width = image.shape[:2]
    sigma = share * height
    fy, fx = torch.fft.fftfreq(height)[:, None], torch.fft.rfftfreq(width)[None, :]
    gain = torch.exp(-2.0 * math.pi**2 * sigma**2 * (fy.square() + fx.square()))
    channels = torch.from_numpy(np.ascontiguousarray(image, dtype=np.float32)).permute(2, 0, 1)
    blurred = torch.fft.irfft2(torch.fft.rfft2(channels) * gain, s=(height, width))
    return blurred.clamp(0.0, 1.0).permute(1, 2, 0).contiguous().numpy()


def periodic_blur(image: np.ndarray, sigma: float) -> np.ndarray:
    """``image`` (H, W, 3) blurred by a Gaussian of ``sigma`` pixels, read as periodic (tiled), so the blur of a
    texture that repeats has no seam at its edges."""
    if sigma > SPATIAL_MAX_SIGMA:
        return softened(image, sigma / image.shape[0])
    height, width = image.shape[:2]
    pad = math.ceil(4.0 * sigma) + 1  # OpenCV's float kernel reaches 4 sigma
    tiled = np.pad(image, ((pad, pad), (pad, pad), (0, 0)), mode="wrap")
    return cv2.GaussianBlur(tiled, (0, 0), sigma)[pad : pad + height, pad : pad + width]
