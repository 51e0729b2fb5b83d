"""3DGS's reconstruction loss, (1 - lambda) L1 + lambda D-SSIM: what fitting minimises and what the
Geometry Preservation Branch's correction phases pull the stylised scene back with."""

from __future__ import annotations

import torch
import torch.nn.functional as F

from .ssim import WINDOW, ssim, ssim_map


def reconstruction_loss(
    rendered: torch.Tensor, target: torch.Tensor, lambda_dssim: float = 0.2, tolerance: float = 0.0
) -> torch.Tensor:
    """3DGS's (1 - lambda) L1 + lambda (1 - SSIM) of (H, W, 3) or (B, H, W, 3) images.

    ``tolerance`` > 0 treats smaller residuals as none: the L1 term counts only the excess, and SSIM
    windows with no residual above it pass no gradient. Adam takes full-size steps on however small
    a gradient, so without this a scene that already fits its targets random-walks (the GPB's case).
    """
    residual = (rendered - target).abs()
    if tolerance <= 0.0:
        return (1.0 - lambda_dssim) * residual.mean() + lambda_dssim * (1.0 - ssim(rendered, target).mean())
    windows = ssim_map(rendered, target)
    batched = residual if residual.dim() == 4 else residual[None]
    wrong = window_max(batched.permute(0, 3, 1, 2)) > tolerance
    windows = torch.where(wrong, windows, windows.detach())
    return (1.0 - lambda_dssim) * F.relu(residual - tolerance).mean() + lambda_dssim * (1.0 - windows.mean())


def window_max(images: torch.Tensor) -> torch.Tensor:
    """The maximum over every ``WINDOW`` x ``WINDOW`` window (stride 1, no padding) of (B, C, H, W) images,
    as rows then columns: the same values as one 2D max pool, in 2 x WINDOW comparisons a pixel, not WINDOW^2."""
    return F.max_pool2d(F.max_pool2d(images, (WINDOW, 1), stride=1), (1, WINDOW), stride=1)
