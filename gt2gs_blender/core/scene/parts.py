"""The parts of a capture, found from its splats' colour and position: a guitar's body, neck and stand, a robot and
the ground it stands on, so an artist can texture one and keep the others.

No trained model: the splats are binned on a grid (``GRIDS``: up to 48 cells along their robust bounds' longest side),
each cell carrying its splats' mean colour in CIE Lab, and neighbouring cells join by graph-based segmentation
(Felzenszwalb and Huttenlocher 2004): cheapest colour edge first, two groups merging while the edge is no larger than
either's largest inner edge plus ``SCALE`` over its size, so a colour boundary stops a part where a gradual shade does
not. Groups under ``MIN_SHARE`` of the splats then join the neighbour they touch most cheaply, or, touching none
(floaters), the part of the nearest cell. Each splat finally takes the part nearest its own colour among those of
its cell and the neighbouring ones (so a boundary runs between splats, not cells); parts are numbered largest first.

numpy only (no torch, no OpenCV), so Blender finds the parts of a splat object in its own Python (``find_parts_in``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .arrays import SplatArrays
from .inria import SH_C0

if TYPE_CHECKING:
    from .gaussians import GaussianScene

GRIDS = (48, 32, 24, 16, 12, 8)
"""Cells along the scene's longest side: the finest at which an occupied cell holds ``PER_CELL`` splats on average
(a part thinner than about a cell joins its neighbours)."""
PER_CELL = 4.0
SCALE = 60.0
"""Felzenszwalb's k, in Lab units times cells: larger makes fewer, larger parts."""
SAME_COLOUR = 12.0
"""Touching groups whose mean colours are nearer than this (CIE Lab units; about five just-noticeable differences)
are one part ..."""
SAME_EDGE = 3.0
"""... and so are groups with two touching cells nearer than this in colour: a shade across a surface, not a
boundary."""
MIN_SHARE = 0.01
"""A part holds at least this share of the splats (smaller groups join their cheapest neighbour)."""
MIN_OPACITY = 0.1
"""Fainter splats do not vote for their cell's colour (they still take its part)."""
BOUNDS_QUANTILE = 0.005
"""The grid spans the splats but this share on each side."""
SRGB_TO_XYZ = np.array([[0.412453, 0.357580, 0.180423], [0.212671, 0.715160, 0.072169], [0.019334, 0.119193, 0.950227]])
"""Linear sRGB to CIE XYZ under D65 (OpenCV's ``COLOR_RGB2Lab`` matrix)."""
WHITE = np.array([0.950456, 1.0, 1.088754])
"""D65's XYZ, Lab's reference white."""


@dataclass(frozen=True)
class Parts:
    """A labelling of a scene's splats into parts, largest first."""

    labels: np.ndarray
    """(N,) int: each splat's part, 0 the largest."""
    colours: np.ndarray
    """(P, 3) float in [0, 1]: each part's mean colour (sRGB), to show in a pick list."""
    sizes: np.ndarray
    """(P,) int: splats per part."""

    def __len__(self) -> int:
        return len(self.sizes)

    def mask(self, part: int) -> np.ndarray:
        """(N,) bool: the splats of ``part``; IndexError naming the parts there are when it is not one."""
        if not 0 <= part < len(self):
            raise IndexError(f"part {part} does not exist: the scene has parts 0 to {len(self) - 1}")
        return self.labels == part


def find_parts(scene: GaussianScene, scale: float = SCALE) -> Parts:
    """The parts of ``scene`` (see the module's docstring); one part for a scene of one colour."""
    return _parts(
        scene.means.detach().double().cpu().numpy(),
        scene.base_colors.detach().float().cpu().numpy(),
        scene.opacities.detach().float().cpu().numpy(),
        scale,
    )


def find_parts_in(scene: SplatArrays, scale: float = SCALE) -> Parts:
    """``find_parts`` of the numpy twin of a scene (Blender's splat objects; no torch needed)."""
    with np.errstate(over="ignore"):
        opacities = 1.0 / (1.0 + np.exp(-scene.opacity_logits.astype(np.float32)))
    return _parts(scene.means.astype(np.float64), 0.5 + SH_C0 * scene.sh_dc.astype(np.float32), opacities, scale)


def _parts(means: np.ndarray, colours: np.ndarray, opacities: np.ndarray, scale: float) -> Parts:
    """The parts of splats at ``means`` (N, 3) of sRGB ``colours`` (N, 3, any range) and ``opacities``."""
    if not len(means):
        return Parts(np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0, np.int64))
    colours = np.clip(colours, 0.0, 1.0).astype(np.float32)
    opacities = opacities.reshape(-1)
    cells, shape = _cells(means)
    occupied, cell_of = np.unique(cells, return_inverse=True)
    lab = srgb_to_lab(colours)
    weight = np.where(opacities >= MIN_OPACITY, opacities, 1e-3).astype(np.float64)
    mean_lab = _cell_means(cell_of, lab, weight, len(occupied))
    edges = _neighbour_edges(occupied, shape, mean_lab)
    counts = np.bincount(cell_of, minlength=len(occupied))
    group = _segment(len(occupied), edges, counts, mean_lab, scale)
    group = _absorb_strays(group, counts, np.stack(np.unravel_index(occupied, shape), axis=1))
    labels = _refined(_numbered(group)[cell_of], cell_of, edges[:, :2].astype(np.int64), lab, weight)
    sizes = np.bincount(labels)
    part_colours = np.stack(
        [np.average(colours[labels == p], axis=0, weights=weight[labels == p]) for p in range(len(sizes))]
    )
    return Parts(labels, part_colours.clip(0.0, 1.0), sizes)


def srgb_to_lab(rgb: np.ndarray) -> np.ndarray:
    """(N, 3) CIE Lab (float64) of sRGB colours in [0, 1], as OpenCV's ``COLOR_RGB2Lab`` of float images."""
    rgb = np.asarray(rgb, np.float64)
    linear = np.where(rgb <= 0.04045, rgb / 12.92, ((rgb + 0.055) / 1.055) ** 2.4)
    xyz = linear @ SRGB_TO_XYZ.T / WHITE
    f = np.where(xyz > 0.008856, np.cbrt(xyz), 7.787 * xyz + 16.0 / 116.0)
    lightness = np.where(xyz[:, 1] > 0.008856, 116.0 * f[:, 1] - 16.0, 903.3 * xyz[:, 1])
    return np.stack([lightness, 500.0 * (f[:, 0] - f[:, 1]), 200.0 * (f[:, 1] - f[:, 2])], axis=1)


def _refined(
    labels: np.ndarray, cell_of: np.ndarray, pairs: np.ndarray, lab: np.ndarray, weight: np.ndarray
) -> np.ndarray:
    """Per splat, the part nearest its own colour among the parts of its cell and the neighbouring cells (a cell
    on a boundary holds splats of both sides, and its mean colour is neither's); parts left under ``MIN_SHARE`` of
    the splats are then given out the same way, and the parts renumbered largest first."""
    n_cells = int(cell_of.max()) + 1
    near = np.zeros((n_cells, int(labels.max()) + 1), bool)
    cell_part = np.zeros(n_cells, np.int64)
    cell_part[cell_of] = labels
    near[np.arange(n_cells), cell_part] = True
    near[pairs[:, 0], cell_part[pairs[:, 1]]] = True
    near[pairs[:, 1], cell_part[pairs[:, 0]]] = True
    for _ in range(2):
        means = np.stack([_mean_or_inf(lab, weight, labels == p) for p in range(near.shape[1])])
        kept = np.bincount(labels, minlength=near.shape[1]) >= MIN_SHARE * len(labels)
        allowed = near[cell_of] & kept
        allowed[~allowed.any(axis=1)] = kept  # a splat with no kept part near takes the nearest colour of all
        distance = ((lab[:, None, :] - means[None, :, :]) ** 2).sum(axis=2)
        labels = np.where(allowed, distance, np.inf).argmin(axis=1)
    return _numbered(labels)


def _mean_or_inf(values: np.ndarray, weight: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """The ``weight``-ed mean of ``values[rows]``, or infinities when there are none (a part no splat holds)."""
    return np.average(values[rows], axis=0, weights=weight[rows]) if rows.any() else np.full(values.shape[1], np.inf)


def _cells(means: np.ndarray) -> tuple[np.ndarray, tuple[int, int, int]]:
    """Each splat's flat cell index on the finest of ``GRIDS`` over the robust bounds dense enough for
    ``PER_CELL`` (outliers clamped to the border cells), and the grid's shape."""
    lo = np.quantile(means, BOUNDS_QUANTILE, axis=0)
    hi = np.quantile(means, 1.0 - BOUNDS_QUANTILE, axis=0)
    for grid in GRIDS:
        size = max(float((hi - lo).max()) / grid, 1e-12)
        shape = tuple(int(v) for v in np.maximum(np.ceil((hi - lo) / size), 1).astype(int))
        index = np.clip(np.floor((means - lo) / size).astype(np.int64), 0, np.array(shape) - 1)
        cells = np.ravel_multi_index(index.T, shape)
        if len(means) >= PER_CELL * len(np.unique(cells)):
            break
    return cells, shape  # type: ignore[return-value]


def _cell_means(cell_of: np.ndarray, values: np.ndarray, weight: np.ndarray, n: int) -> np.ndarray:
    """(n, C) the ``weight``-ed mean of ``values`` per cell."""
    total = np.stack([np.bincount(cell_of, weights=weight * values[:, c], minlength=n) for c in range(values.shape[1])])
    return (total / np.bincount(cell_of, weights=weight, minlength=n)).T


def _neighbour_edges(occupied: np.ndarray, shape: tuple[int, int, int], lab: np.ndarray) -> np.ndarray:
    """(E, 3) [cell, cell, Lab distance] between occupied cells that share a face, edge or corner."""
    coords = np.stack(np.unravel_index(occupied, shape), axis=1)
    position = {int(c): k for k, c in enumerate(occupied)}
    offsets = [(dx, dy, dz) for dx in (0, 1) for dy in (-1, 0, 1) for dz in (-1, 0, 1) if (dx, dy, dz) > (0, 0, 0)]
    pairs = []
    for offset in offsets:
        other = coords + offset
        inside = np.all((other >= 0) & (other < shape), axis=1)
        flat = np.ravel_multi_index(other[inside].T, shape)
        partner = np.array([position.get(int(f), -1) for f in flat], dtype=np.int64)
        found = partner >= 0
        pairs.append(np.stack([np.flatnonzero(inside)[found], partner[found]], axis=1))
    joined = np.concatenate(pairs) if pairs else np.zeros((0, 2), np.int64)
    distance = np.linalg.norm(lab[joined[:, 0]] - lab[joined[:, 1]], axis=1)
    return np.column_stack([joined, distance])


def _segment(n: int, edges: np.ndarray, counts: np.ndarray, lab: np.ndarray, scale: float) -> np.ndarray:
    """(n,) a group per cell: Felzenszwalb's merge on ``edges`` (cells weighted by their splat ``counts``); then
    touching groups merged whose mean colours lie within ``SAME_COLOUR`` or that touch across cells within
    ``SAME_EDGE`` (the halves of one shaded surface that the noise of its colours kept apart), and groups under
    ``MIN_SHARE`` of the splats merged along their cheapest edge."""
    parent = np.arange(n)
    size = counts.astype(np.float64).copy()
    inner = np.zeros(n)
    total = lab * size[:, None]

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    def join(a: int, b: int, weight: float) -> None:
        parent[b] = a
        size[a] += size[b]
        total[a] += total[b]
        inner[a] = max(inner[a], inner[b], weight)

    order = np.argsort(edges[:, 2], kind="stable")
    cells = max(float(counts.mean()), 1.0)
    for a, b, weight in edges[order]:
        ra, rb = root(int(a)), root(int(b))
        if ra != rb and weight <= min(inner[ra] + scale * cells / size[ra], inner[rb] + scale * cells / size[rb]):
            join(ra, rb, weight)
    for a, b, weight in edges[order]:
        ra, rb = root(int(a)), root(int(b))
        same = weight < SAME_EDGE or np.linalg.norm(total[ra] / size[ra] - total[rb] / size[rb]) < SAME_COLOUR
        if ra != rb and same:
            join(ra, rb, weight)
    floor = MIN_SHARE * counts.sum()
    for a, b, weight in edges[order]:
        ra, rb = root(int(a)), root(int(b))
        if ra != rb and min(size[ra], size[rb]) < floor:
            join(ra, rb, weight)
    return np.array([root(i) for i in range(n)])


def _absorb_strays(group: np.ndarray, counts: np.ndarray, coords: np.ndarray) -> np.ndarray:
    """``group`` with the cells of groups still under ``MIN_SHARE`` of the splats (strays no neighbour touches:
    floaters) given the group of the nearest cell of a larger one."""
    totals = np.bincount(group, weights=counts, minlength=len(group))
    small = totals[group] < MIN_SHARE * counts.sum()
    if not small.any() or small.all():
        return group
    big = np.flatnonzero(~small)
    out = group.copy()
    for cell in np.flatnonzero(small):
        nearest = big[np.argmin(((coords[big] - coords[cell]) ** 2).sum(axis=1))]
        out[cell] = group[nearest]
    return out


def _numbered(groups: np.ndarray) -> np.ndarray:
    """``groups`` renumbered 0, 1, ... by size, largest first (ties by first appearance)."""
    unique, inverse, counts = np.unique(groups, return_inverse=True, return_counts=True)
    rank = np.empty(len(unique), np.int64)
    rank[np.argsort(-counts, kind="stable")] = np.arange(len(unique))
    return rank[inverse]
