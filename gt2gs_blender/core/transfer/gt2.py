"""The GT² loss's geometry (paper §3.2, Eq. 5-7): prior angles carried from view to view, and matching.

Views are visited in an order where neighbours overlap. For each feature cell of view v the cell's
covered pixels are lifted with the original scene's depth, projected into the previous view v-1 and
kept where that view sees the same surface (occlusion test on depth). The least-squares 2x2 map
between the cell's pixels in the two views gives, by SVD (polar decomposition), the rotation beta
by which a texture direction turns from view v-1 to view v. The prior angle of the cell is then
theta' + beta, with theta' the angle matched at the cell's position in view v-1; the first view's
prior is the user's start angle (orientation control). Each cell's target is the bank feature
minimising (1 - cos) + lambda_p * |prior - theta| (angles wrapped to [0, 180] degrees).

Angles follow the texture bank (``texture_bank`` module notes): theta = counter-clockwise on screen,
a texture direction d becomes [[c, s], [-s, c]] d. With M the pixel map from view v to view v-1 and
R = [[cos phi, -sin phi], [sin phi, cos phi]] its rotation, a texture at theta' in view v-1 shows at
theta' + phi in view v, so beta = phi = atan2(R10, R00). The authors' code adds beta in radians to
degrees and never warps the prior map; neither is reproduced.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F

from ..cameras.camera import Camera
from ..cameras.warp import expected_depth, pixel_centres, warp_image
from .losses import COSINE_EPS
from .texture_bank import TextureBank, pixel_cells

MIN_CELL_PIXELS = 3
"""A cell needs this many pixels seen in both views to fit its 2x2 map (and at least half its pixels)."""
MATCH_BLOCK = 1 << 22
"""Largest cells x bank block of costs built at once."""


def wrap_degrees(angle: torch.Tensor) -> torch.Tensor:
    """Angles in [0, 360)."""
    return torch.remainder(angle, 360.0)


def angle_distance(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Absolute angular difference in [0, 180] degrees (so 359 and 1 are 2 apart)."""
    d = torch.remainder(a - b, 360.0)
    return torch.minimum(d, 360.0 - d)


def rotation_angle(maps: torch.Tensor) -> torch.Tensor:
    """Angle phi (degrees) of the rotation nearest each 2x2 map (...,2,2), by SVD: R = U V^T with
    det(R) = +1 (a reflected map gives the rotation of its nearest proper part)."""
    u, _, vh = torch.linalg.svd(maps)
    flip = torch.where(torch.linalg.det(u @ vh) < 0, -1.0, 1.0).to(u)
    r = torch.cat([u[..., :1], u[..., 1:] * flip[..., None, None]], dim=-1) @ vh
    return torch.rad2deg(torch.atan2(r[..., 1, 0], r[..., 0, 0]))


def fit_linear_maps(
    src: torch.Tensor, dst: torch.Tensor, cell: torch.Tensor, weight: torch.Tensor, n_cells: int
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Per cell, the least-squares 2x2 map M with dst - mean(dst) ~ M (src - mean(src)).

    ``src``/``dst`` (P,2) point pairs, ``cell`` (P,) their cell index, ``weight`` (P,) 1 for pairs
    to use and 0 otherwise. Returns the maps (n,2,2), the mean of ``dst`` per cell (n,2) and the
    pair count per cell (n,). Float64 sums; cells whose points are collinear get a zero map.
    """
    src, dst, w = src.double(), dst.double(), weight.double()
    count = torch.zeros(n_cells, dtype=torch.float64, device=src.device).index_add_(0, cell, w)

    def cell_sum(values: torch.Tensor) -> torch.Tensor:
        return torch.zeros(n_cells, *values.shape[1:], dtype=torch.float64, device=src.device).index_add_(
            0, cell, values * w.reshape(-1, *([1] * (values.dim() - 1)))
        )

    n = count.clamp_min(1.0)
    src_mean = cell_sum(src) / n[:, None]
    dst_mean = cell_sum(dst) / n[:, None]
    sxx = cell_sum(src[:, :, None] * src[:, None, :]) / n[:, None, None] - src_mean[:, :, None] * src_mean[:, None, :]
    sdx = cell_sum(dst[:, :, None] * src[:, None, :]) / n[:, None, None] - dst_mean[:, :, None] * src_mean[:, None, :]
    det = torch.linalg.det(sxx)
    well_posed = det.abs() > 1e-9 * sxx.diagonal(dim1=-2, dim2=-1).sum(-1).square().clamp_min(1e-30)
    safe = torch.where(well_posed[:, None, None], sxx, torch.eye(2, dtype=sxx.dtype, device=sxx.device))
    maps = sdx @ torch.linalg.inv(safe)
    maps = torch.where(well_posed[:, None, None], maps, torch.zeros_like(maps))
    return maps, dst_mean, count * well_posed


@dataclass(frozen=True)
class PriorLink:
    """How the feature cells of a view see the previous view: ``valid`` (h,w) cells with a prior,
    ``source`` (h,w) the previous view's cell index (row-major) each one lands on, ``beta`` (h,w)
    the texture rotation from the previous view to this one, in degrees."""

    valid: torch.Tensor
    source: torch.Tensor
    beta: torch.Tensor

    def prior_angles(self, previous_angles: torch.Tensor) -> torch.Tensor:
        """(h,w) prior angle per cell from the previous view's matched angles (its (h',w') map, NaN
        where nothing was matched); NaN where the cell has no prior."""
        carried = previous_angles.reshape(-1)[self.source] + self.beta
        return torch.where(
            self.valid & torch.isfinite(carried), wrap_degrees(carried), torch.full_like(carried, math.nan)
        )


def prior_link(
    camera: Camera,
    depth: torch.Tensor,
    alpha: torch.Tensor,
    previous: Camera,
    previous_depth: torch.Tensor,
    previous_alpha: torch.Tensor,
    feature_hw: tuple[int, int],
    previous_feature_hw: tuple[int, int] | None = None,
) -> PriorLink:
    """The :class:`PriorLink` of ``camera`` to ``previous`` from the original scene's raw rendered
    depths (sum T alpha z) and alphas of both views (H,W)."""
    h, w = feature_hw
    ph, pw = previous_feature_hw or feature_hw
    z, pz = expected_depth(depth, alpha), expected_depth(previous_depth, previous_alpha)
    blank = torch.zeros(*previous_depth.shape, 1, dtype=previous_depth.dtype, device=previous_depth.device)
    warp = warp_image(blank, pz, previous, camera, z, src_alpha=previous_alpha, dst_alpha=alpha, mode="nearest")
    cell = pixel_cells(camera.height, camera.width, feature_hw, depth.device)
    src = pixel_centres(camera, depth.device).reshape(-1, 2)
    dst = warp.src_uv.reshape(-1, 2)
    used = warp.valid.reshape(-1)
    maps, landing, count = fit_linear_maps(src, dst, cell, used.double(), h * w)
    pixels = torch.bincount(cell, minlength=h * w).double()
    valid = (count >= MIN_CELL_PIXELS) & (count >= 0.5 * pixels)
    col = (landing[:, 0] * pw / previous.width).floor().long().clamp(0, pw - 1)
    row = (landing[:, 1] * ph / previous.height).floor().long().clamp(0, ph - 1)
    beta = torch.where(
        valid, rotation_angle(torch.where(valid[:, None, None], maps, torch.eye(2).to(maps))), torch.zeros_like(count)
    )
    return PriorLink(valid.reshape(h, w), (row * pw + col).reshape(h, w), beta.float().reshape(h, w))


def view_order(cameras: Sequence[Camera]) -> list[int]:
    """A visiting order where consecutive views overlap: a greedy nearest-neighbour chain over the
    camera centres and viewing directions, from view 0 (ordered orbits and captures come back as-is)."""
    centres = np.stack([c.center for c in cameras])
    forwards = np.stack([c.forward for c in cameras])
    scale = max(float(np.linalg.norm(centres - centres.mean(0), axis=1).max()), 1e-9)
    order, left = [0], set(range(1, len(cameras)))
    while left:
        last = order[-1]
        cost = {
            j: np.linalg.norm(centres[j] - centres[last]) / scale + (1.0 - forwards[j] @ forwards[last]) for j in left
        }
        nearest = min(cost, key=lambda j: (cost[j], j))
        order.append(nearest)
        left.remove(nearest)
    return order


@dataclass(frozen=True)
class Match:
    """Targets of one view: ``indices`` (h,w) bank rows (prior-guided), ``angles`` (h,w) their theta,
    ``free_angles`` (h,w) the theta of the unconstrained nearest feature (for the distortion map)."""

    indices: torch.Tensor
    angles: torch.Tensor
    free_angles: torch.Tensor


def angle_layout(theta: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Rows grouped by angle, for matching one angle at a time: the distinct angles (A,) ascending
    and an (A, L) table of row positions (-1 pads) in row order within each angle."""
    angles, inverse, counts = torch.unique(theta, return_inverse=True, return_counts=True)
    order = torch.sort(inverse, stable=True).indices
    starts = torch.cumsum(counts, 0) - counts
    slot = torch.arange(len(theta), device=theta.device) - starts[inverse[order]]
    table = torch.full(
        (len(angles), int(counts.max()) if len(counts) else 0), -1, dtype=torch.long, device=theta.device
    )
    table[inverse[order], slot] = order
    return angles, table


@torch.no_grad()
def match_with_prior(
    feats: torch.Tensor,
    bank: TextureBank,
    prior: torch.Tensor,
    lambda_prior: float,
    groups: torch.Tensor | None = None,
    cells: torch.Tensor | None = None,
) -> Match:
    """Per cell of ``feats`` (C,h,w): argmin over the bank (restricted to the cell's depth group when
    ``groups`` (h,w) is given and >= 0) of (1 - cos) + ``lambda_prior`` * angle_distance(prior, theta)
    per degree; NaN ``prior`` cells match on cosine alone. ``cells`` (h,w) bool: match only these
    (the texture loss counts only covered cells); the others get row 0 as a placeholder.

    The prior term is the same for every row of one angle, so each cell takes its nearest row per
    angle first and adds the penalty to those A minima only (A = angles, not the M rows): the same
    targets as costing every row, at about the price of the cosine products alone. A bank with a
    ``match_basis`` (:func:`.texture_bank.compact_bank`) is matched on its projected channels."""
    c, h, w = feats.shape
    queries = F.normalize(feats.reshape(c, -1).T, dim=1, eps=COSINE_EPS)
    if bank.match_basis is not None and bank.match_features is not None:  # PCA: cosine on d < C channels
        queries = F.normalize(queries @ bank.match_basis.to(queries), dim=1, eps=COSINE_EPS)
        rows = bank.match_features.to(queries)
    else:
        rows = F.normalize(bank.features.to(queries), dim=1, eps=COSINE_EPS)
    flat_prior = prior.reshape(-1).to(queries)
    flat_groups = None if groups is None else groups.reshape(-1).to(queries.device)
    wanted = (
        torch.ones(h * w, dtype=torch.bool, device=queries.device)
        if cells is None
        else cells.reshape(-1).to(queries.device)
    )
    best = torch.zeros(h * w, dtype=torch.long, device=queries.device)
    free = torch.zeros_like(best)
    for g in [None] if flat_groups is None else torch.unique(flat_groups[wanted]).tolist():
        members = wanted if g is None else wanted & (flat_groups == g)
        cells_g = members.nonzero().squeeze(1)
        bank_rows = (
            torch.arange(len(rows), device=queries.device)
            if g is None or g < 0
            else (bank.k.to(queries.device) == g).nonzero().squeeze(1)
        )
        group_rows = rows[bank_rows]
        angles, table = angle_layout(bank.theta.to(queries.device)[bank_rows])
        blocks = table.numel() == len(bank_rows) and bool(
            torch.equal(table.reshape(-1), torch.arange(len(bank_rows), device=table.device))
        )
        step = max(1, MATCH_BLOCK // max(table.numel(), 1))
        for start in range(0, len(cells_g), step):
            part = cells_g[start : start + step]
            cost = 1.0 - queries[part] @ group_rows.T
            if blocks:  # rows already ordered by angle in equal runs (every bank built here): a view
                per_angle = cost.view(len(part), *table.shape)
            else:
                per_angle = torch.where(table >= 0, cost[:, table.clamp_min(0)], torch.inf)
            nearest, slot = per_angle.min(dim=2)
            free_angle = nearest.argmin(dim=1)
            penalty = lambda_prior * angle_distance(flat_prior[part, None], angles[None].to(queries))
            best_angle = (nearest + torch.nan_to_num(penalty, nan=0.0)).argmin(dim=1)
            free[part] = bank_rows[table[free_angle, slot.gather(1, free_angle[:, None]).squeeze(1)]]
            best[part] = bank_rows[table[best_angle, slot.gather(1, best_angle[:, None]).squeeze(1)]]
    return Match(best.reshape(h, w), bank.theta[best].reshape(h, w), bank.theta[free].reshape(h, w))


def distortion(match: Match) -> torch.Tensor:
    """Paper's Φ per cell in [0, 1]: the angle between the prior-guided and the free match, folded
    to [0, 90] degrees (a texture turned by 180 degrees is as aligned as one not turned) over 90."""
    gap = angle_distance(match.angles, match.free_angles)
    return torch.minimum(gap, 180.0 - gap) / 90.0
