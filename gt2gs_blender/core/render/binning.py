"""Tile lists: for every 8x8 tile of every camera, the entries that touch it, front to back."""

from __future__ import annotations

from dataclasses import dataclass

import torch


@dataclass
class TileBins:
    """``pair_gauss[offsets[t]:offsets[t+1]]`` are the entries of tile t (camera-major, row-major)."""

    offsets: torch.Tensor  # (n_tiles + 1,) int32
    pair_gauss: torch.Tensor  # (P,) int32 entry indices
    pair_tile: torch.Tensor | None = None  # (P,) int32 tile of each slot (portable binning only)


def bin_entries_torch(
    tile_bbox: torch.Tensor, cam_ids: torch.Tensor, depths: torch.Tensor, n_cams: int, tiles_x: int, tiles_y: int
) -> TileBins:
    """Portable binning: a global depth sort, one (entry, tile) pair per covered tile, a stable sort by tile.

    Per-pair values are spread with repeat_interleave (no gathers) and the tile keys sorted as int32,
    which torch sorts several times faster than int64."""
    device = tile_bbox.device
    n_tiles = n_cams * tiles_x * tiles_y
    order = torch.argsort(depths)
    x0, y0, x1, y1 = tile_bbox.index_select(0, order).long().unbind(1)
    nx = (x1 - x0 + 1).clamp_min(0)
    counts = nx * (y1 - y0 + 1).clamp_min(0)
    first = torch.cumsum(counts, 0) - counts
    base = cam_ids.index_select(0, order) * (tiles_x * tiles_y) + y0 * tiles_x + x0
    total = int(counts.sum())
    local = torch.arange(total, device=device) - torch.repeat_interleave(first, counts, output_size=total)
    nx_pair = torch.repeat_interleave(nx, counts, output_size=total)
    row = torch.div(local, nx_pair, rounding_mode="floor")
    key = torch.repeat_interleave(base, counts, output_size=total) + row * tiles_x + (local - row * nx_pair)
    key, perm = torch.sort(key.to(torch.int32), stable=True)
    owner = torch.repeat_interleave(order, counts, output_size=total).index_select(0, perm)
    offsets = torch.zeros(n_tiles + 1, dtype=torch.int64, device=device)
    offsets[1:] = torch.cumsum(torch.bincount(key, minlength=n_tiles), 0)
    return TileBins(offsets=offsets.to(torch.int32), pair_gauss=owner.to(torch.int32), pair_tile=key)
