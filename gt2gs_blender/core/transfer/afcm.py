"""Adaptive Fine-grained Control Module (paper §3.3, Eq. 8-9): where the texture may overwrite detail.

Per feature cell: W = lambda_d (1 - I_d) + lambda_f (1 - I_f) + lambda_phi (1 - Phi), with I_d the
normalised depth (the cell's depth group over K - 1: near cells learn the texture most), I_f the
normalised high-frequency energy of the content image (an 8x8-block DCT, one block per feature cell:
detailed regions keep their detail) and Phi the distortion map of :func:`gt2.distortion`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import torch
import torch.nn.functional as F

BLOCK = 8
"""DCT block side: each feature cell's image area is resampled to one 8x8 block, as in JPEG."""
HIGH_BAND = slice(4, 8)
"""The [4:8, 4:8] quarter of the block's DCT coefficients counts as high frequency (authors' code)."""
NORM_QUANTILE = 0.99
"""Frequency energies are divided by this quantile over all covered cells of all views (robust max)."""


@dataclass(frozen=True)
class AFCMWeights:
    """The paper's {lambda_d, lambda_f, lambda_phi}."""

    depth: float = 0.8
    frequency: float = 0.8
    distortion: float = 0.25


def dct_matrix(n: int = BLOCK, dtype: torch.dtype = torch.float64) -> torch.Tensor:
    """The orthonormal DCT-II matrix D (n,n): coefficients of a block B are D B D^T (as cv2.dct)."""
    k = torch.arange(n, dtype=dtype)[:, None]
    i = torch.arange(n, dtype=dtype)[None, :]
    d = torch.cos(math.pi * (2 * i + 1) * k / (2 * n)) * math.sqrt(2.0 / n)
    d[0] /= math.sqrt(2.0)
    return d


def block_dct(gray: torch.Tensor, block: int = BLOCK) -> torch.Tensor:
    """DCT-II coefficients (h,w,block,block) of each block of a (h*block, w*block) grey image."""
    height, width = gray.shape
    if height % block or width % block:
        raise ValueError(f"image {height}x{width} is not a whole number of {block}x{block} blocks")
    d = dct_matrix(block, torch.float64).to(gray.device)
    blocks = gray.double().reshape(height // block, block, width // block, block).permute(0, 2, 1, 3)
    return d @ blocks @ d.T


def high_frequency_energy(image: torch.Tensor, feature_hw: tuple[int, int]) -> torch.Tensor:
    """Sum of |high-band DCT coefficients| (h,w) of the grey ``image`` (H,W,3) resampled so that each
    feature cell is one 8x8 block (area filter when shrinking, bilinear when enlarging)."""
    h, w = feature_hw
    gray = (image[..., 0] * 0.299 + image[..., 1] * 0.587 + image[..., 2] * 0.114)[None, None]
    size = (h * BLOCK, w * BLOCK)
    shrink = size[0] <= image.shape[0] and size[1] <= image.shape[1]
    gray = F.interpolate(
        gray.float(), size=size, mode="area" if shrink else "bilinear", **({} if shrink else {"align_corners": False})
    )[0, 0]
    return block_dct(gray)[..., HIGH_BAND, HIGH_BAND].abs().sum(dim=(-1, -2)).float()


def normalise_frequency(energies: Sequence[torch.Tensor], masks: Sequence[torch.Tensor]) -> list[torch.Tensor]:
    """Energies of all views divided by their robust maximum (the ``NORM_QUANTILE`` over covered
    cells of every view, so a surface is weighted alike in every view), clamped to [0, 1]."""
    covered = torch.cat([e[m] for e, m in zip(energies, masks)])
    top = float(torch.quantile(covered.double(), NORM_QUANTILE)) if covered.numel() else 0.0
    if not top > 0:
        return [torch.zeros_like(e) for e in energies]
    return [(e / top).clamp(0.0, 1.0) for e in energies]


def depth_level(groups: torch.Tensor | None, n_groups: int, like: torch.Tensor) -> torch.Tensor:
    """I_d per cell in [0, 1] from the depth group map (0 nearest .. 1 farthest; uncovered cells and
    a single group count as near)."""
    if groups is None or n_groups < 2:
        return torch.zeros_like(like)
    return (groups.clamp_min(0).to(like.dtype) / (n_groups - 1)).to(like.device)


def afcm_weight(
    depth: torch.Tensor, frequency: torch.Tensor, distortion: torch.Tensor, weights: AFCMWeights = AFCMWeights()
) -> torch.Tensor:
    """Paper Eq. 8: W = lambda_d (1 - I_d) + lambda_f (1 - I_f) + lambda_phi (1 - Phi), all (h,w) in [0, 1]."""
    return (
        weights.depth * (1.0 - depth) + weights.frequency * (1.0 - frequency) + weights.distortion * (1.0 - distortion)
    )
