"""The scene kept under the laid-out texture (``keep_scene``, ``scene_colour``, ``scene_brightness``): its light
and dark, edges, parts, colours and overall brightness.

Laid over a whole capture, the plain texture hid the scene (the fern's SSIM to the original fell from 0.49
to 0.05). Each splat keeps three things of the scene (``layout_shade``, one (N, ``ROW``) row per splat):
- its shade: its own original luminance over the bright end of the scene's, to the power ``keep_scene`` (0:
  the texture's own brightness everywhere; 1: the texture times the scene's luminance, an albedo under the
  capture's own shading);
- a share ``scene_colour`` of its own colour mixed under the shaded texture, so parts that differ in hue only
  (a donut's pink icing and beige dough, a robot's red eyes in a grey face) stay apart, and more of its hue where
  that colour is a rare, vivid accent (``keep_accents``, :mod:`.accents`), at the texture's light and dark;
- the scene's overall brightness: one exposure for the whole run (``brightness_exposure``), so the mix's mean
  luminance is the scene's (``scene_brightness`` 1). Shaded by the scene's luminance over its bright end, a
  texture darker than white came out darker than the capture, a white one lighter. Lighter goes by a power
  (``mix^(1/e)`` maps 0..1 onto itself, so a light object brightens without clipping: a gain clipped the donut's
  icing), darker by a gain (``e * mix``: the kept light and dark keep their ratios; a power cannot darken
  white, and crushed the rest to black); both keep the texture's light and dark in order.
``under_scene`` is the one rule that applies them, to the splats, the layout term's images and the sketch
preview alike. The row follows each splat through densification (an optimiser attachment) to the detail
split's children.
``shade_softness`` first averages the luminance over neighbours within that share of a repeat
(``spatial_blur``; the layout term's images average their surface points the same way), so only the
scene's broad light and dark darkens the texture, not its specks.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import torch
import torch.nn.functional as F

from ..scene.gaussians import GaussianScene
from .accents import ColourShare
from .tone import luma

ROW = 8
"""A splat's kept-scene row: the texture's gain, the colour added (3), the exposure, the accent's hue (3)."""
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
EXPOSURE_RANGE = (0.2, 5.0)
"""The exposure stays within these: a gain of 0.2 at the darkest, the power 1/5 at the lightest (a black
texture on a white scene asks for more, and would get a grey wash)."""
EXPOSURE_SPLATS = 1024
EXPOSURE_TEXELS = 32
""":func:`brightness_exposure` averages over at most this many splats and the texture at this many texels a side
(area-averaged, as the layout prefilters it to a splat's footprint): the mean is all it needs."""
EXPOSURE_STEPS = 32
"""Bisection steps on the exposure's logarithm (its range over 2^32: far below a grey level)."""


def layout_shade(
    scene: GaussianScene,
    rows: torch.Tensor | None = None,
    softness: float = 0.0,
    keep: float = 1.0,
    colour: float | ColourShare = 0.0,
    texture: np.ndarray | None = None,
    brightness: float = 0.0,
    bright: torch.Tensor | None = None,
    parts: torch.Tensor | None = None,
) -> torch.Tensor:
    """(N, ``ROW``) what each splat of ``rows`` (all when None) keeps of the scene (:func:`kept_scene`): its colour,
    averaged over its neighbours within about ``softness`` (a world length, 0: its own), that colour's
    luminance over the bright end of those splats' (or over each splat's own ``bright`` (N,), the luminance its
    material shows fully lit: :func:`material_bright`), to the power ``keep`` (:func:`shading`), its part's hue
    (``parts`` (N, 3): each splat's part's mean colour, for *Keep Hues*), and ``brightness`` of the exposure that
    gives ``texture`` laid over them the scene's mean luminance (:func:`brightness_exposure`, in stops); the other
    splats keep the texture as it is."""
    colours = scene.base_colors.detach().clamp(0.0, 1.0)
    kept = kept_scene(torch.ones(len(scene), dtype=scene.dtype, device=scene.device), colours, 0.0)
    part = slice(None) if rows is None else rows
    if rows is not None and not bool(rows.any()):
        return kept
    seen = colours[part]
    if softness > 0:
        points, weights = scene.means.detach()[part], scene.opacities.detach()[part]
        seen = torch.stack([spatial_blur(points, seen[:, c], weights, softness) for c in range(3)], dim=1)
    luminance = luma(seen)
    lit_at = None if bright is None else bright[part].to(luminance)
    of_parts = None if parts is None else parts[part].to(luminance)
    mixed = kept_scene(shading(luminance, keep=keep, bright=lit_at), seen, colour, parts=of_parts)
    if texture is not None and brightness > 0:
        weights = coverage_weights(scene.scales.detach()[part], scene.opacities.detach()[part])
        mixed[:, 4] = brightness_exposure(texture, mixed, luminance, weights) ** brightness
    kept[part] = mixed
    return kept


def coverage_weights(scales: torch.Tensor, opacities: torch.Tensor) -> torch.Tensor:
    """(N,) how much of a view each splat covers, roughly: its opacity times the area of its two largest axes
    (``scales`` (N, 3)), capped at their 99th percentile, so a few huge background splats do not outweigh the
    object."""
    ordered = scales.float().sort(dim=1).values
    area = ordered[:, 1] * ordered[:, 2]
    if len(area) > 1:
        area = area.clamp(max=float(torch.quantile(area[:: max(1, len(area) // SPATIAL_BOUNDS_SAMPLE)], 0.99)))
    return opacities.float().reshape(-1) * area


def brightness_exposure(
    texture: np.ndarray, kept: torch.Tensor, luminance: torch.Tensor, weights: torch.Tensor
) -> float:
    """The exposure (:func:`exposed`) that gives ``texture`` (H, W, 3 in 0..1) laid over ``kept`` (N, ``ROW``,
    :func:`under_scene`, its exposure ignored) the ``weights``-averaged mean of the scene's ``luminance`` (N,):
    every splat paired with every texel of the texture area-averaged to ``EXPOSURE_TEXELS`` a side, as a layout
    tiling the surface samples it. 1 when nothing is weighed."""
    step = max(1, len(kept) // EXPOSURE_SPLATS)
    rows, w = kept[::step].float().cpu(), weights[::step].float().cpu().clamp_min(0.0)
    if not len(rows) or float(w.sum()) <= 0:
        return 1.0
    w = w / w.sum()
    target = float(w @ luminance[::step].float().cpu().clamp(0.0, 1.0))
    side = (EXPOSURE_TEXELS, EXPOSURE_TEXELS)
    small = cv2.resize(np.asarray(texture[..., :3], np.float32), side, interpolation=cv2.INTER_AREA)
    texels = torch.from_numpy(small.reshape(-1, 3))
    mixed = mix(texels[None], rows[:, None]).clamp(0.0, 1.0)  # (splats, texels, 3)
    return exposure_for(luma(mixed), target, w)


def exposure_for(luminance: torch.Tensor, target: float, weights: torch.Tensor | None = None) -> float:
    """The exposure (within ``EXPOSURE_RANGE``) at which :func:`exposed_luminance` of ``luminance`` (rows, samples)
    averages ``target``, the rows weighted by ``weights`` (summing to 1; None: alike): bisection on its log, as the
    mean grows with the exposure."""
    rows = luminance.reshape(len(luminance), -1)
    w = torch.full((len(rows),), 1.0 / max(len(rows), 1)) if weights is None else weights.to(rows)
    low, high = (math.log(e) for e in EXPOSURE_RANGE)
    for _ in range(EXPOSURE_STEPS):
        mid = 0.5 * (low + high)
        mean = float(w @ exposed_luminance(rows, math.exp(mid)).mean(dim=1))
        low, high = (mid, high) if mean < target else (low, mid)
    return math.exp(0.5 * (low + high))


def exposed(colours: torch.Tensor, exposure: torch.Tensor | float) -> torch.Tensor:
    """``colours`` (..., 3 in 0..1) at ``exposure`` (a float, or one per row broadcast against them): darker by
    the gain ``e`` below 1; lighter above, to the luminance ``Y^(1/e)`` with the hue and saturation kept (a power
    per channel washed colours out), nearing white only where a channel would pass 1 (:func:`lit`). Nothing
    leaves 0..1, the order of light and dark is kept, and 1 leaves the colours as they are."""
    exposure = torch.as_tensor(exposure, dtype=colours.dtype, device=colours.device)
    inside = colours.clamp(0.0, 1.0)
    luminance = luma(inside)
    wanted = exposed_luminance(luminance, exposure.squeeze(-1).clamp_min(1.0))
    return torch.where(exposure <= 1.0, colours * exposure, lit(inside, luminance, wanted))


def exposed_luminance(luminance: torch.Tensor, exposure: torch.Tensor | float) -> torch.Tensor:
    """The luminance :func:`exposed` gives colours of ``luminance`` (in 0..1): ``e * Y`` below 1, ``Y^(1/e)``
    above."""
    exposure = torch.as_tensor(exposure, dtype=luminance.dtype, device=luminance.device)
    lighter = luminance.clamp(0.0, 1.0).pow(1.0 / exposure.clamp_min(1.0))
    return torch.where(exposure <= 1.0, luminance * exposure, lighter)


def lit(colours: torch.Tensor, luminance: torch.Tensor, wanted: torch.Tensor) -> torch.Tensor:
    """``colours`` (..., 3 in 0..1, of ``luminance``) brought to the higher luminance ``wanted``: scaled (hue and
    saturation kept) as far as the brightest channel allows, then mixed toward white for the rest."""
    scaled = colours * (wanted / luminance.clamp_min(1e-12))[..., None]
    fitted = scaled / scaled.amax(dim=-1, keepdim=True).clamp_min(1.0)
    y = luma(fitted)
    short = ((wanted - y) / (1.0 - y).clamp_min(1e-12)).clamp(0.0, 1.0)
    return fitted + short[..., None] * (1.0 - fitted)


def kept_scene(
    shade: torch.Tensor,
    colours: torch.Tensor,
    colour: float | ColourShare,
    exposure: float = 1.0,
    parts: torch.Tensor | None = None,
) -> torch.Tensor:
    """(N, ``ROW``): the share of the texture's brightness (``shade``, (N,)) that stays once ``colour`` of the
    scene's own ``colours`` (N, 3) is mixed under it (one share for all, or each colour's own: :class:`ColourShare`),
    what that mix adds, the mix's exposure (the scene's brightness, :func:`exposed`), and an accent's and a part's
    hue (``parts``: (N, 3) the mean colour of each one's part, or None), which the texture's luminance scales
    (:meth:`ColourShare.mixed`): what :func:`under_scene` applies."""
    exposures = torch.full_like(shade[:, None], exposure)
    colours = colours.to(shade)
    if isinstance(colour, ColourShare):
        share, added, hue = colour.mixed(colours, shade, parts)
    else:
        share, added, hue = colour, colour * colours, torch.zeros_like(colours)
    return torch.cat([(1.0 - share) * shade[:, None], added, exposures, hue], dim=1)


def under_scene(texture: torch.Tensor, kept: torch.Tensor) -> torch.Tensor:
    """(N, 3) ``texture`` colours laid over the scene ``kept`` (N, ``ROW``) row by row (:func:`kept_scene`), at
    the row's exposure (:func:`exposed`)."""
    kept = kept.to(texture)
    mixed = mix(texture, kept)
    exposures = kept[:, 4:5]
    if bool((exposures == 1.0).all()):
        return mixed
    return exposed(mixed, exposures)


def mix(texture: torch.Tensor, kept: torch.Tensor) -> torch.Tensor:
    """(..., 3) ``texture`` colours (..., 3) mixed with the scene ``kept`` (..., ``ROW``, broadcast against them)
    before the exposure: the shaded texture, the mixed-in share of the scene's own colour and an accent's hue at
    the texture's luminance."""
    luminance = luma(texture)
    return texture * kept[..., :1] + kept[..., 1:4] + luminance[..., None] * kept[..., 5:8]


def laid_exposure(kept: torch.Tensor, rows: torch.Tensor | None) -> float:
    """The exposure ``kept`` (:func:`layout_shade`) gives the texture laid on ``rows`` (all when None): one for
    the whole run, which the layout term's images take too."""
    laid = kept if rows is None else kept[rows]
    return float(laid[0, 4]) if len(laid) else 1.0


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


def shading(
    luminance: torch.Tensor,
    reference: torch.Tensor | None = None,
    keep: float = 1.0,
    bright: torch.Tensor | None = None,
) -> torch.Tensor:
    """``luminance`` over the :func:`bright_end` of ``reference`` (default: ``luminance`` itself), or over
    ``bright`` (one per value: the luminance taken as fully lit there), clipped to [``SHADE_MIN``, 1], to the
    power ``keep``: the light and shade the layout and the sketch preview keep."""
    if bright is None:
        values = luminance if reference is None else reference
        if not values.numel():
            return torch.ones_like(luminance)
        bright = torch.tensor(bright_end(values), dtype=torch.float64)
    return (luminance / bright.to(luminance).clamp_min(1e-6)).clamp(SHADE_MIN, 1.0) ** keep


def bright_end(values: torch.Tensor) -> float:
    """The ``SHADE_QUANTILE`` of ``values`` (1 when empty): the luminance a scene shows where it is fully lit."""
    flat = values.detach().float().reshape(-1)
    if not len(flat):
        return 1.0
    rank = max(1, round(SHADE_QUANTILE * len(flat)))
    return max(float(flat.kthvalue(rank).values), 1e-6)


def material_bright(luminance: torch.Tensor, labels: torch.Tensor, material: float) -> torch.Tensor:
    """(N,) the luminance each splat counts as fully lit: the scene's :func:`bright_end` to the power
    ``material`` times its part's median (``labels`` (N,), a part each) to the power ``1 - material``.

    A dark capture's dark is mostly its material (dark wood, black metal), not its light; taken against the
    whole scene's bright end it darkened the texture with it. Against its own part's median, each part's light
    and shade stays while its own brightness goes (``material`` 0: the brighter half of each part fully lit)."""
    overall = bright_end(luminance)
    if material >= 1.0 or not len(luminance):
        return torch.full_like(luminance, overall)
    parts, index = labels.unique(return_inverse=True)
    medians = torch.stack([luminance[index == k].float().median() for k in range(len(parts))]).to(luminance)
    return overall**material * medians.clamp_min(1e-6)[index] ** (1.0 - material)
