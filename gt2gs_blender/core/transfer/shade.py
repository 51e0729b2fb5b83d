"""The scene kept under the laid-out texture (``keep_scene``, ``scene_colour``): its light and dark, edges,
parts and colours.

Laid over a whole capture, the plain texture hid the scene (the fern's SSIM to the original fell from 0.49
to 0.05). Each splat keeps two things of the scene (``layout_shade``, one (N, 4) row per splat):
- its shade: its own original luminance over the bright end of the scene's, to the power ``keep_scene`` (0:
  the texture's own brightness everywhere; 1: the texture times the scene's luminance, an albedo under the
  capture's own shading);
- a share ``scene_colour`` of its own colour mixed under the shaded texture, so parts that differ in hue only
  (a donut's pink icing and beige dough, a robot's red eyes in a grey face) stay apart.
``under_scene`` is the one rule that applies them, to the splats, the layout term's images and the sketch
preview alike. The row follows each splat through densification (an optimiser attachment) to the detail
split's children.
``shade_softness`` first averages the luminance over neighbours within that share of a repeat
(``spatial_blur``; the layout term's images average their surface points the same way), so only the
scene's broad light and dark darkens the texture, not its specks.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F

from ..scene.gaussians import GaussianScene
from .metrics import LUMA

SHADE_MIN = 0.02
"""Luminance ratios below this count as this (a black splat is a very dark one, not a zero to a power)."""
SHADE_QUANTILE = 0.95
"""The bright end of the scene's luminance (full texture brightness): this quantile, so a few specks do not set it."""
SPATIAL_GRID = 128
""":func:`spatial_blur`'s grid has at most this many cells along the scene's longest side ..."""
SPATIAL_CELLS_PER_SIGMA = 2
"""... and otherwise this many per sigma."""
SPATIAL_MIN_WEIGHT = 1e-6
"""Weights (opacities) below this count as this: among nearly transparent splats the average is a plain one."""
SPATIAL_BOUNDS_QUANTILE = 0.005
SPATIAL_BOUNDS_MARGIN = 3.0
"""The grid spans the points but this share of them on each side, widened by this many sigmas: points
beyond (floaters) read the grid's border."""
SPATIAL_BOUNDS_SAMPLE = 1_000_000
"""The bounds' quantiles come from at most about this many of the points (torch.quantile's size limit)."""


def layout_shade(
    scene: GaussianScene,
    rows: torch.Tensor | None = None,
    softness: float = 0.0,
    keep: float = 1.0,
    colour: float = 0.0,
) -> torch.Tensor:
    """(N, 4) what each splat of ``rows`` (all when None) keeps of the scene (:func:`kept_scene`): its colour,
    averaged over its neighbours within about ``softness`` (a world length, 0: its own), and that colour's
    luminance over the bright end of those splats', to the power ``keep`` (:func:`shading`); the other splats
    keep the texture as it is."""
    colours = scene.base_colors.detach().clamp(0.0, 1.0)
    kept = kept_scene(torch.ones(len(scene), dtype=scene.dtype, device=scene.device), colours, 0.0)
    part = slice(None) if rows is None else rows
    if rows is not None and not bool(rows.any()):
        return kept
    seen = colours[part]
    if softness > 0:
        points, weights = scene.means.detach()[part], scene.opacities.detach()[part]
        seen = torch.stack([spatial_blur(points, seen[:, c], weights, softness) for c in range(3)], dim=1)
    luminance = seen @ torch.tensor(LUMA, dtype=seen.dtype, device=seen.device)
    kept[part] = kept_scene(shading(luminance, keep=keep), seen, colour)
    return kept


def kept_scene(shade: torch.Tensor, colours: torch.Tensor, colour: float) -> torch.Tensor:
    """(N, 4): the share of the texture's brightness (``shade``, (N,)) that stays once ``colour`` of the scene's
    own ``colours`` (N, 3) is mixed under it, then that colour's share: what :func:`under_scene` applies."""
    return torch.cat([(1.0 - colour) * shade[:, None], colour * colours.to(shade)], dim=1)


def under_scene(texture: torch.Tensor, kept: torch.Tensor) -> torch.Tensor:
    """(N, 3) ``texture`` colours laid over the scene ``kept`` (N, 4) row by row (:func:`kept_scene`): the
    shaded texture plus the mixed-in share of the scene's own colour."""
    kept = kept.to(texture)
    return texture * kept[:, :1] + kept[:, 1:]


def spatial_blur(points: torch.Tensor, values: torch.Tensor, weights: torch.Tensor, sigma: float) -> torch.Tensor:
    """(N,) ``values`` at ``points`` averaged over their neighbours with Gaussian weights of width ``sigma``
    times ``weights``: a normalised convolution on a grid (each point splatted to and read from its eight
    cells, trilinearly; cells no wider than sigma / 2 unless the grid would exceed ``SPATIAL_GRID`` cells on
    a side). Outliers beyond the grid read its border but add nothing to it; a point with no weight near it
    keeps its value. Runs on the CPU (a small grid), returns on ``values``' device."""
    if not len(points) or sigma <= 0:
        return values.clone()
    p = points.detach().float().cpu()
    v = values.detach().float().cpu()
    sample = p[:: max(1, len(p) // SPATIAL_BOUNDS_SAMPLE)]
    margin = SPATIAL_BOUNDS_MARGIN * sigma
    lo = torch.quantile(sample, SPATIAL_BOUNDS_QUANTILE, dim=0) - margin
    hi = torch.quantile(sample, 1.0 - SPATIAL_BOUNDS_QUANTILE, dim=0) + margin
    inside = ((p >= lo) & (p <= hi)).all(dim=1)
    cell = max(sigma / SPATIAL_CELLS_PER_SIGMA, float((hi - lo).max()) / (SPATIAL_GRID - 2), 1e-12)
    dims = (torch.floor((hi - lo) / cell).long() + 2).tolist()
    x = ((p - lo) / cell).clamp(min=torch.zeros(3), max=torch.tensor(dims, dtype=p.dtype) - 1.0 - 1e-4)
    base = x.floor().long()
    frac = x - base
    w = torch.where(inside, weights.detach().float().cpu().clamp_min(SPATIAL_MIN_WEIGHT), 0.0)
    corners = []
    for corner in range(8):
        offset = torch.tensor([(corner >> 2) & 1, (corner >> 1) & 1, corner & 1])
        share = torch.where(offset.bool(), frac, 1.0 - frac).prod(dim=1)
        index = base + offset
        corners.append(((index[:, 0] * dims[1] + index[:, 1]) * dims[2] + index[:, 2], share))
    grid = torch.zeros(2, dims[0] * dims[1] * dims[2])
    for index, share in corners:
        grid[0].index_add_(0, index, share * w)
        grid[1].index_add_(0, index, share * w * v)
    grid = _gaussian_blur_3d(grid.view(2, *dims), sigma / cell).reshape(2, -1)
    mass = sum(share * grid[0, index] for index, share in corners)
    total = sum(share * grid[1, index] for index, share in corners)
    blurred = torch.where(mass > 1e-12, total / mass.clamp_min(1e-12), v)
    return blurred.to(values)


def _gaussian_blur_3d(grid: torch.Tensor, sigma_cells: float) -> torch.Tensor:
    """(C, X, Y, Z) ``grid`` blurred by a Gaussian of ``sigma_cells`` along each axis (zero outside)."""
    radius = max(1, math.ceil(3.0 * sigma_cells))
    taps = torch.arange(-radius, radius + 1, dtype=grid.dtype)
    kernel = torch.exp(-0.5 * (taps / sigma_cells) ** 2)
    kernel = (kernel / kernel.sum()).view(1, 1, -1)
    for axis in (1, 2, 3):
        moved = grid.movedim(axis, -1)
        shape = moved.shape
        blurred = F.conv1d(moved.reshape(-1, 1, shape[-1]), kernel, padding=radius)
        grid = blurred.view(shape).movedim(-1, axis)
    return grid


def shading(luminance: torch.Tensor, reference: torch.Tensor | None = None, keep: float = 1.0) -> torch.Tensor:
    """``luminance`` over the ``SHADE_QUANTILE`` of ``reference`` (default: ``luminance`` itself), clipped to
    [``SHADE_MIN``, 1], to the power ``keep``: the light and shade the layout and the sketch preview keep."""
    values = (luminance if reference is None else reference).detach().float().reshape(-1)
    if not len(values):
        return torch.ones_like(luminance)
    rank = max(1, round(SHADE_QUANTILE * len(values)))
    bright = max(float(values.kthvalue(rank).values), 1e-6)
    return (luminance / bright).clamp(SHADE_MIN, 1.0) ** keep
