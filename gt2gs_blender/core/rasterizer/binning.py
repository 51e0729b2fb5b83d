"""Tile lists: for every 8x8 tile of every camera, the entries that touch it, front to back."""
from __future__ import annotations

from dataclasses import dataclass

import torch


@dataclass
class TileBins:
    """``pair_gauss[offsets[t]:offsets[t+1]]`` are the entries of tile t (camera-major, row-major)."""

    offsets: torch.Tensor     # (n_tiles + 1,) int32
    pair_gauss: torch.Tensor  # (P,) int32 entry indices


def bin_entries_torch(
    tile_bbox: torch.Tensor, cam_ids: torch.Tensor, depths: torch.Tensor, n_cams: int, tiles_x: int, tiles_y: int
) -> TileBins:
    """Portable binning: a global depth sort, one (entry, tile) pair per covered tile, a stable sort by tile."""
    device = tile_bbox.device
    n_tiles = n_cams * tiles_x * tiles_y
    order = torch.argsort(depths)
    bb = tile_bbox[order].long()
    nx = (bb[:, 2] - bb[:, 0] + 1).clamp_min(0)
    counts = nx * (bb[:, 3] - bb[:, 1] + 1).clamp_min(0)
    owner = torch.repeat_interleave(torch.arange(order.numel(), device=device), counts)
    first = torch.cumsum(counts, 0) - counts
    local = torch.arange(owner.numel(), device=device) - first[owner]
    tx = bb[owner, 0] + local % nx[owner]
    ty = bb[owner, 1] + torch.div(local, nx[owner], rounding_mode="floor")
    key = cam_ids[order][owner] * (tiles_x * tiles_y) + ty * tiles_x + tx
    key, perm = torch.sort(key, stable=True)
    offsets = torch.zeros(n_tiles + 1, dtype=torch.int64, device=device)
    offsets[1:] = torch.cumsum(torch.bincount(key, minlength=n_tiles), 0)
    return TileBins(offsets=offsets.to(torch.int32), pair_gauss=order[owner[perm]].to(torch.int32))
