"""Work a run can skip without changing what it computes much (docs/speed.md, "Skips"), each switchable in
:class:`~.config.TransferConfig` and measured by ``bench/tradeoff.py --skips``:

- SH bands whose coefficients are all zero are never evaluated (:func:`used_sh_degree`);
- the texture bank is compacted: fewer angles for a texture without a dominant local orientation
  (:func:`texture_anisotropy`, :func:`angles_for`), near-duplicate features merged
  (:func:`near_duplicates`), optional PCA to fewer channels for matching (:func:`pca_basis`);
- views that add no new coverage are dropped (:func:`redundant_views`);
- a phase stops once its loss plateaus (:class:`Plateau`).

(Hidden Gaussians are skipped in :mod:`.transfer`; the bank's disk cache is in :mod:`.texture_bank`.)
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np
import torch
import torch.nn.functional as F

from ..cameras.camera import Camera
from ..cameras.warp import expected_depth, warp_image
from ..scene.gaussians import GaussianScene, sh_coeff_count

SH_ZERO = 1e-6
"""A band whose coefficients are all at most this (absolute) contributes nothing visible."""


# -- SH bands ------------------------------------------------------------------------------------------
def used_sh_degree(scene: GaussianScene, tol: float = SH_ZERO) -> int:
    """The highest SH degree with a coefficient above ``tol`` in any Gaussian (0 when none above DC)."""
    rest = scene.sh_rest.detach().abs()
    for degree in range(scene.sh_degree, 0, -1):
        lo, hi = sh_coeff_count(degree - 1) - 1, sh_coeff_count(degree) - 1
        if rest.shape[0] and bool((rest[:, lo:hi] > tol).any()):
            return degree
    return 0


# -- texture anisotropy -> angle count ------------------------------------------------------------------
ANISOTROPY_SIGMA = 3.0
"""Window (Gaussian sigma, px) over which the structure tensor is averaged: a local orientation."""
ANISOTROPY_RANGE = (0.2, 0.5)
"""Coherence at or below the low end needs the fewest angles, at or above the high end all of them."""
MIN_ANGLES = 8


def texture_anisotropy(texture: np.ndarray, height: int = 128, sigma: float = ANISOTROPY_SIGMA) -> float:
    """How strongly oriented the texture is locally, in [0, 1]: the structure tensor's coherence
    (l1 - l2) / (l1 + l2) of every ``sigma`` window, averaged weighted by gradient energy, on the
    grey texture resized to ``height``. Stripes (even herringbone: two orientations, each locally
    strong) are near 1; white noise and flat images near 0."""
    grey = np.asarray(texture, dtype=np.float32)[..., :3].mean(axis=2)
    h, w = grey.shape
    if h != height:
        grey = cv2.resize(grey, (max(1, round(w * height / h)), height), interpolation=cv2.INTER_AREA)
    gx = cv2.Sobel(grey, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(grey, cv2.CV_32F, 0, 1, ksize=3)
    jxx, jyy, jxy = (cv2.GaussianBlur(a, (0, 0), sigma) for a in (gx * gx, gy * gy, gx * gy))
    trace = jxx + jyy
    gap = np.sqrt((jxx - jyy) ** 2 + 4.0 * jxy**2)
    total = float(trace.sum())
    return float(gap.sum() / total) if total > 1e-12 else 0.0


def angles_for(
    anisotropy: float,
    n_angles: int,
    min_angles: int = MIN_ANGLES,
    coherence_range: tuple[float, float] = ANISOTROPY_RANGE,
) -> int:
    """Angle count for a texture of this anisotropy: ``n_angles`` (the user's resolution) for an
    oriented texture, down to ``min_angles`` for an isotropic one, linearly in between; a divisor
    of ``n_angles`` so the angles are a subset of the full grid (and of its start angle)."""
    lo, hi = coherence_range
    t = min(1.0, max(0.0, (anisotropy - lo) / (hi - lo)))
    want = min_angles + t * (n_angles - min_angles)
    divisors = [d for d in range(1, n_angles + 1) if n_angles % d == 0 and d >= min(min_angles, n_angles)]
    return min(divisors, key=lambda d: (d < want, abs(d - want)))


# -- near-duplicate features -----------------------------------------------------------------------------
def near_duplicates(
    features: torch.Tensor, blocks: torch.Tensor, threshold: float = 0.99, chunk: int = 2048
) -> torch.Tensor:
    """Bool (M,): rows with an earlier row of the same block (e.g. the same depth group and angle)
    at cosine similarity above ``threshold``. Dropping them keeps every distinct feature: each
    dropped row has a twin before it (chains of twins are dropped down to their first row)."""
    rows = F.normalize(features.float(), dim=1)
    drop = torch.zeros(len(rows), dtype=torch.bool, device=rows.device)
    for b in torch.unique(blocks).tolist():
        index = (blocks == b).nonzero().squeeze(1)
        x = rows[index]
        for start in range(0, len(x), chunk):
            part = x[start : start + chunk]
            sim = part @ x[: start + len(part)].T  # against every earlier-or-same row of the block
            earlier = (
                torch.arange(start + len(part), device=rows.device)[None]
                < (torch.arange(len(part), device=rows.device) + start)[:, None]
            )
            drop[index[start : start + len(part)]] = ((sim > threshold) & earlier).any(dim=1)
    return drop


# -- PCA for matching -----------------------------------------------------------------------------------
def pca_basis(features: torch.Tensor, channels: int) -> torch.Tensor:
    """(C, d) orthonormal basis of the ``channels`` leading principal directions of the unit rows
    (uncentred: cosine similarity is about directions from the origin)."""
    x = F.normalize(features.float(), dim=1)
    _, _, vh = torch.linalg.svd(x, full_matrices=False)
    return vh[:channels].T.contiguous()


# -- views that add no coverage --------------------------------------------------------------------------
COVERAGE_SIZE = 64
"""Views are compared at this many pixels on the long side (coverage, not detail)."""


def redundant_views(
    cameras: Sequence[Camera],
    depths: Sequence[torch.Tensor],
    alphas: Sequence[torch.Tensor],
    order: Sequence[int],
    min_new: float = 0.02,
    size: int = COVERAGE_SIZE,
) -> list[int]:
    """Views (indices) to drop, visited in ``order``: a view is dropped when less than ``min_new``
    of its covered pixels are not already seen, by depth reprojection, in the views kept before it.
    The first view is always kept."""
    small = [_downscale(cam, d, a, size) for cam, d, a in zip(cameras, depths, alphas)]
    kept: list[int] = []
    dropped: list[int] = []
    for v in order:
        cam, z, alpha = small[v]
        covered = alpha >= 0.5
        if not kept:
            kept.append(v)
            continue
        if not bool(covered.any()):
            dropped.append(v)  # sees nothing of the scene
            continue
        seen = torch.zeros_like(covered)
        for k in kept:
            kcam, kz, kalpha = small[k]
            warp = warp_image(
                torch.zeros(*kz.shape, 1, dtype=kz.dtype, device=kz.device),
                kz,
                kcam,
                cam,
                z,
                src_alpha=kalpha,
                dst_alpha=alpha,
                mode="nearest",
            )
            seen |= warp.valid
        new = float((covered & ~seen).sum()) / max(1, int(covered.sum()))
        (dropped if new < min_new else kept).append(v)
    return sorted(dropped)


def _downscale(
    camera: Camera, depth: torch.Tensor, alpha: torch.Tensor, size: int
) -> tuple[Camera, torch.Tensor, torch.Tensor]:
    """The camera scaled to ``size`` px on its long side, its expected depth and alpha resampled
    (nearest depth: no mixing of surfaces across edges)."""
    scale = min(1.0, size / max(camera.width, camera.height))
    cam = camera.scaled(scale) if scale < 1.0 else camera
    z = expected_depth(depth, alpha)
    if (cam.height, cam.width) != tuple(z.shape):
        z = F.interpolate(z[None, None], size=(cam.height, cam.width), mode="nearest")[0, 0]
        alpha = F.interpolate(alpha[None, None], size=(cam.height, cam.width), mode="area")[0, 0]
    return cam, z, alpha


# -- convergence ----------------------------------------------------------------------------------------
@dataclass
class Plateau:
    """Stop a phase when its loss has stopped falling: the mean of the last ``window`` losses is
    less than ``tol`` (relative) below the mean of the ``window`` before (both windows complete).
    ``window`` 0 never stops."""

    window: int
    tol: float
    losses: list[float] = field(default_factory=list)

    def update(self, loss: float) -> bool:
        """Record one step's loss; True when the phase should stop now."""
        self.losses.append(float(loss))
        w = self.window
        if w < 1 or len(self.losses) < 2 * w:
            return False
        before = sum(self.losses[-2 * w : -w]) / w
        last = sum(self.losses[-w:]) / w
        if not (math.isfinite(before) and math.isfinite(last)):
            return False
        return (before - last) < self.tol * abs(before)
