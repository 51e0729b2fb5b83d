"""Structural similarity (SSIM), differentiable, as pytorch_msssim computes it.

Gaussian window 11 x 11, sigma 1.5, *valid* windows only (no padding), constants K1 = 0.01,
K2 = 0.03; the score is the mean of the SSIM map over pixels and channels. The same function is the
evaluation metric (checked against pytorch_msssim and skimage values) and, as 1 - SSIM, the D-SSIM
term of the 3DGS reconstruction loss. Images are channels-last, as the rasterizer renders them.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

WINDOW = 11
SIGMA = 1.5
K1, K2 = 0.01, 0.03


def gaussian_window(
    size: int = WINDOW,
    sigma: float = SIGMA,
    *,
    dtype: torch.dtype = torch.float32,
    device: torch.device | str | None = None,
) -> torch.Tensor:
    """The normalised 1D Gaussian (size,) whose outer product is the 2D SSIM window."""
    x = torch.arange(size, dtype=torch.float64, device=device) - (size - 1) / 2.0
    g = torch.exp(-(x * x) / (2.0 * sigma * sigma))
    return (g / g.sum()).to(dtype)


def _blur(x: torch.Tensor, window: torch.Tensor) -> torch.Tensor:
    """Separable valid-window Gaussian filter of (B, C, H, W), one channel at a time."""
    channels = x.shape[1]
    kx = window.reshape(1, 1, 1, -1).expand(channels, 1, 1, -1)
    ky = window.reshape(1, 1, -1, 1).expand(channels, 1, -1, 1)
    return F.conv2d(F.conv2d(x, kx, groups=channels), ky, groups=channels)


def ssim_map(x: torch.Tensor, y: torch.Tensor, *, data_range: float = 1.0) -> torch.Tensor:
    """Per-window SSIM (B, C, H-10, W-10) of images (B, H, W, C) or (H, W, C)."""
    if x.shape != y.shape:
        raise ValueError(f"SSIM needs images of one shape, got {tuple(x.shape)} and {tuple(y.shape)}")
    if x.dim() == 3:
        x, y = x[None], y[None]
    if x.dim() != 4 or min(x.shape[1], x.shape[2]) < WINDOW:
        raise ValueError(f"SSIM needs (B,H,W,C) or (H,W,C) images of at least {WINDOW}x{WINDOW}, got {tuple(x.shape)}")
    x, y = x.permute(0, 3, 1, 2), y.permute(0, 3, 1, 2)
    window = gaussian_window(dtype=x.dtype, device=x.device)
    c1, c2 = (K1 * data_range) ** 2, (K2 * data_range) ** 2
    mu_x, mu_y = _blur(x, window), _blur(y, window)
    var_x = _blur(x * x, window) - mu_x * mu_x
    var_y = _blur(y * y, window) - mu_y * mu_y
    cov = _blur(x * y, window) - mu_x * mu_y
    luminance = (2 * mu_x * mu_y + c1) / (mu_x * mu_x + mu_y * mu_y + c1)
    return luminance * (2 * cov + c2) / (var_x + var_y + c2)


def ssim(x: torch.Tensor, y: torch.Tensor, *, data_range: float = 1.0) -> torch.Tensor:
    """Per-image SSIM (B,) of (B, H, W, C) images, or a scalar for one (H, W, C) image."""
    per_image = ssim_map(x, y, data_range=data_range).flatten(1).mean(1)
    return per_image[0] if x.dim() == 3 else per_image
