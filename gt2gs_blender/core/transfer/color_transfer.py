"""ARF's linear colour transfer: give the scene's colours the texture's mean and covariance.

From the content pixels x (all pixels of all views) and the texture pixels,
``A = U_s S_s^(1/2) U_s^T  U_c S_c^(-1/2) U_c^T`` and ``b = mu_s - A mu_c``, so that ``A x + b`` has
the texture's mean and covariance (U S U^T: eigendecompositions of the 3x3 covariances, float64).

The same map is applied exactly to a Gaussian scene in SH space. A Gaussian's colour is
``0.5 + C0 f_dc + sum_k Y_k(d) f_k``; mapping it to ``A colour + b`` for every direction d means
``f_dc' = (A (0.5 + C0 f_dc) + b - 0.5) / C0`` and ``f_k' = A f_k`` (the rest bands are linear in
colour, without the offset). A render then composites ``A C + b alpha`` over a black background,
which is what ``apply_to_images`` gives premultiplied renders when passed their alpha. The identity
holds wherever the rasterizer's per-Gaussian clamp at 0 is inactive.

Degenerate inputs never produce NaN: content eigenvalues are floored at the variance of 8-bit
quantisation noise (and at 1e-4 of the largest), so a grey or constant content image maps onto the
texture's mean along its missing directions instead of blowing up; a constant texture gives A = 0.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable
from dataclasses import replace

import numpy as np
import torch

from ..scene.gaussians import SH_C0, GaussianScene

log = logging.getLogger(__name__)

QUANTISATION_VARIANCE = (1.0 / 255.0) ** 2 / 12.0
"""Variance of 8-bit rounding noise: directions with less content variance carry no colour."""

RELATIVE_EIGEN_FLOOR = 1e-4
"""Content eigenvalues are also floored at this fraction of the largest one."""

ImageLike = torch.Tensor | np.ndarray


def fit_color_transform(
    content: ImageLike | Iterable[ImageLike],
    texture: ImageLike,
    *,
    weights: ImageLike | Iterable[ImageLike] | None = None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """The float64 map (A (3,3), b (3,)) taking the content colours' statistics to the texture's.

    ``content``: channels-last RGB images in [0, 1], one (B,H,W,3) batch or an iterable of (H,W,3)
    arrays or tensors; ``texture`` (H,W,3) likewise.
    ``weights``: optional per-pixel weights matching ``content`` without the channel axis, e.g.
    the render alphas (coverage-weighted statistics) or a boolean mask; None weighs pixels equally.
    """
    images = list(content)
    masks = [None] * len(images) if weights is None else list(weights)
    if len(masks) != len(images):
        raise ValueError(f"{len(masks)} weight maps for {len(images)} content images")
    mu_c, cov_c = _weighted_moments(zip(images, masks, strict=True))
    mu_s, cov_s = _weighted_moments([(texture, None)])
    whiten = _sym_power(cov_c, -0.5, floor=max(QUANTISATION_VARIANCE, RELATIVE_EIGEN_FLOOR * _largest_eig(cov_c)))
    colour = _sym_power(cov_s, 0.5, floor=0.0)
    matrix = colour @ whiten
    return matrix, mu_s - matrix @ mu_c


def apply_to_images(
    images: torch.Tensor,
    matrix: torch.Tensor,
    offset: torch.Tensor,
    *,
    alpha: torch.Tensor | None = None,
    clamp: bool = True,
) -> torch.Tensor:
    """``A x + b`` on channels-last images (..., 3), in their dtype.

    With ``alpha`` (..., ) the images are taken as renders composited over black (premultiplied):
    the offset is scaled by alpha, matching a render of ``apply_to_scene``'s result. ``clamp`` keeps
    the result in [0, 1] (in [0, alpha] for premultiplied images).
    """
    a = matrix.to(images)
    b = offset.to(images)
    coverage = None if alpha is None else alpha.to(images)[..., None]
    out = images @ a.T + (b if coverage is None else b * coverage)
    if not clamp:
        return out
    return out.clamp(0.0, 1.0) if coverage is None else torch.minimum(out.clamp_min(0.0), coverage)


def apply_to_scene(
    scene: GaussianScene, matrix: torch.Tensor, offset: torch.Tensor, *, clamp: bool = True
) -> GaussianScene:
    """The scene whose rendered colours are ``A colour + b`` from every direction (module notes).

    ``clamp`` keeps each Gaussian's DC colour in [0, 1] (the number clamped is logged); clamped
    Gaussians no longer follow the exact identity, the others do.
    """
    a = matrix.to(dtype=torch.float64, device=scene.device)
    b = offset.to(dtype=torch.float64, device=scene.device)
    base = (0.5 + SH_C0 * scene.sh_dc.detach().double()) @ a.T + b
    if clamp:
        outside = int(((base < 0.0) | (base > 1.0)).any(dim=1).sum())
        if outside:
            log.info("colour transfer: clamped the colour of %d of %d Gaussians into [0, 1]", outside, len(scene))
        base = base.clamp(0.0, 1.0)
    sh_dc = ((base - 0.5) / SH_C0).to(scene.sh_dc.dtype)
    sh_rest = (scene.sh_rest.detach().double() @ a.T).to(scene.sh_rest.dtype)
    return replace(scene, sh_dc=sh_dc, sh_rest=sh_rest)


def _weighted_moments(pairs: Iterable[tuple[ImageLike, ImageLike | None]]) -> tuple[torch.Tensor, torch.Tensor]:
    """Weighted mean (3,) and covariance (3,3) in float64, accumulated image by image.

    Pixels are shifted by the first pixel before accumulating (the shifted-data algorithm): the
    covariance of a constant image is then exactly 0 instead of rounding noise of E[x^2] - E[x]^2,
    whose square root (~1e-7) the whitening would amplify into a visible colour change.
    """
    total = torch.zeros((), dtype=torch.float64)
    first = torch.zeros(3, dtype=torch.float64)
    second = torch.zeros(3, 3, dtype=torch.float64)
    shift: torch.Tensor | None = None
    for image, weight in pairs:
        x = torch.as_tensor(image).detach().reshape(-1, 3).to("cpu", torch.float64)
        if shift is None and len(x):
            shift = x[0].clone()
        if shift is not None:
            x = x - shift
        w = (
            torch.ones(len(x), dtype=torch.float64)
            if weight is None
            else (torch.as_tensor(weight).detach().reshape(-1).to("cpu", torch.float64))
        )
        if len(w) != len(x):
            raise ValueError(f"weight map with {len(w)} pixels for an image with {len(x)}")
        total += w.sum()
        first += w @ x
        second += (x * w[:, None]).T @ x
    if total <= 0:
        raise ValueError("colour transfer needs at least one pixel with positive weight")
    mean = first / total
    cov = second / total - torch.outer(mean, mean)
    return mean + (0.0 if shift is None else shift), 0.5 * (cov + cov.T)


def _largest_eig(cov: torch.Tensor) -> float:
    return float(torch.linalg.eigvalsh(cov)[-1])


def _sym_power(cov: torch.Tensor, power: float, *, floor: float) -> torch.Tensor:
    """``U diag(max(lambda, floor)^power) U^T`` for a symmetric 3x3 matrix."""
    values, vectors = torch.linalg.eigh(cov)
    scaled = values.clamp_min(floor) ** power
    return (vectors * scaled) @ vectors.T
