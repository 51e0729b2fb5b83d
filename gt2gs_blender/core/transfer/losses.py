"""The stylisation loss pieces: cosine distance and nearest texture features (NNFM, paper Eq. 3), content,
the layout's pixels, image TV, scale regulariser.

Conventions that differ from the authors' code on purpose (docs/architecture.md, "The method and the
authors' code"): cosine similarity is taken over the CHANNEL axis of feature maps (theirs normalises over
height), and TV differences pixels along HEIGHT and WIDTH (theirs differences channels and height).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from .hue_path import off_path
from .tone import chroma, luma

COSINE_EPS = 1e-8
"""Norm floor when normalising feature vectors (a zero vector has cosine 0 with everything)."""

DEFAULT_CHUNK_BYTES = 64 * 2**20
"""Memory bound of one block of the query x bank similarity matrix."""


def cosine_distance(a: torch.Tensor, b: torch.Tensor, dim: int = -1) -> torch.Tensor:
    """``1 - cos(a, b)`` along ``dim`` (the channel axis), with a norm floor against zero vectors."""
    return 1.0 - (F.normalize(a, dim=dim, eps=COSINE_EPS) * F.normalize(b, dim=dim, eps=COSINE_EPS)).sum(dim=dim)


@torch.no_grad()
def nearest_features(
    queries: torch.Tensor, bank: torch.Tensor, *, chunk_bytes: int = DEFAULT_CHUNK_BYTES
) -> torch.Tensor:
    """Index (N,) of the bank row (M,C) most cosine-similar to each query (N,C); first index on ties."""
    q = F.normalize(queries.detach(), dim=1, eps=COSINE_EPS)
    m = F.normalize(bank.detach().to(q), dim=1, eps=COSINE_EPS)
    return _blockwise_argmax(q, m, chunk_bytes)


def _blockwise_argmax(q: torch.Tensor, m: torch.Tensor, chunk_bytes: int) -> torch.Tensor:
    """argmax_j q_i . m_j over blocks of at most ``chunk_bytes`` of similarities (bank split if needed)."""
    item = q.element_size()
    bank_step = max(1, min(len(m), chunk_bytes // item))
    query_step = max(1, chunk_bytes // (item * bank_step))
    best = torch.empty(len(q), dtype=torch.long, device=q.device)
    for q0 in range(0, len(q), query_step):
        block = q[q0 : q0 + query_step]
        best_sim = torch.full((len(block),), -torch.inf, dtype=q.dtype, device=q.device)
        best_idx = torch.zeros(len(block), dtype=torch.long, device=q.device)
        for m0 in range(0, len(m), bank_step):
            sim, idx = (block @ m[m0 : m0 + bank_step].T).max(dim=1)
            better = sim > best_sim
            best_sim = torch.where(better, sim, best_sim)
            best_idx = torch.where(better, idx + m0, best_idx)
        best[q0 : q0 + len(block)] = best_idx
    return best


def light_only(image: torch.Tensor) -> torch.Tensor:
    """``image`` (..., 3) unchanged, whose gradient reaches its channels only as one even shift of all three (lighter
    or darker, its hue untouched): what the feature losses see under *Texture Loss Keeps Hue*."""
    grey = image.mean(-1, keepdim=True)
    return image.detach() + (grey - grey.detach())


def content_loss(feats: torch.Tensor, content_feats: torch.Tensor) -> torch.Tensor:
    """Mean squared difference between rendered and content features (any matching shapes)."""
    return F.mse_loss(feats, content_feats)


HUE_WEIGHT = 4.0
"""How much more a step of hue off the path from the texture's to the scene's costs in the layout term than
the same step in light and dark: a tint that neither the texture nor the capture has (the guitar's pink and
green patches under woven straw, the fern's rainbow flecks under toy bricks) is bought 4x dearer."""


def layout_loss(image: torch.Tensor, layout: torch.Tensor, scene: torch.Tensor) -> torch.Tensor:
    """Mean absolute difference between a render (H, W, 3) and the laid-out texture (H, W, 4: colour and
    coverage), on the pixels the layout covers: in luma, the texture's light and dark pixel for pixel (a
    black texel counts as much as any other), and ``HUE_WEIGHT`` x how far the render's colour differences
    (R - Y, B - Y) lie off the straight path from the texture's to the scene's (H, W, 3, the original
    render) at that pixel: a spot may drift back toward the capture's own hue for free, while a hue that
    neither has (magenta dots at woven straw's crossings, bought with one channel) costs far more than
    the same step in light and dark."""
    covered = layout[..., 3] > 0
    if not bool(covered.any()):
        return image.sum() * 0.0
    result, texture, original = image[covered], layout[..., :3][covered], scene[covered]
    return (
        luma(result - texture).abs() + HUE_WEIGHT * off_path(chroma(result), chroma(texture), chroma(original))
    ).mean()


def tv_loss(image: torch.Tensor, *, channels_last: bool = True) -> torch.Tensor:
    """Image total variation: the mean of the squared neighbour differences along height and the
    mean along width, averaged (ARF's squared form). ``image`` is (B,H,W,C) or, with
    ``channels_last=False``, (B,C,H,W); a missing batch axis is fine."""
    height_axis, width_axis = (-3, -2) if channels_last else (-2, -1)
    dy = image.diff(dim=height_axis)
    dx = image.diff(dim=width_axis)
    return 0.5 * (dy.square().mean() + dx.square().mean())


def anisotropy(log_scales: torch.Tensor) -> torch.Tensor:
    """Per Gaussian, largest / second-largest scale (>= 1), from the log-scales (stable)."""
    top2 = torch.topk(log_scales, k=2, dim=-1).values
    return torch.exp(top2[..., 0] - top2[..., 1])


def scale_regulariser(log_scales: torch.Tensor, threshold: float | torch.Tensor = 1.0) -> torch.Tensor:
    """Mean over Gaussians of ``relu(largest / second-largest scale - threshold)``.

    The authors' code penalises the plain ratio (mean of largest/second, weight 0.1) to keep
    Gaussians from turning into needles that show as streaks; the default ``threshold`` 1 gives
    exactly that gradient (the value is shifted by 1, so an isotropic scene scores 0). A larger
    threshold tolerates elongation up to that ratio; a tensor (N,) gives each Gaussian its own.
    """
    return F.relu(anisotropy(log_scales) - threshold).mean()
