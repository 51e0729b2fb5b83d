"""The portable backend: compositing in plain torch (CPU or CUDA), all tiles at once, in depth chunks.

Each step takes the next chunk of entries of every still-active tile's list and composites them
for the tile's 64 pixels with cumulative products. The backward recomputes the same chunks front
to back (the colour behind an entry is the final colour minus the running prefix, both dotted with the
pixel's colour gradient so only scalars per pixel are kept), so memory stays bounded by one chunk instead of growing with the number of (entry, pixel) pairs.
"""
from __future__ import annotations

from dataclasses import dataclass

import torch

from .binning import TileBins, bin_entries_torch
from .projection import ALPHA_MIN, TILE, Projection, tile_grid

CHUNK_MIN = 4
CHUNK_MAX = 1024
CHUNK_ELEMENTS = 1 << 20
"""A step covers (active tiles x chunk x 64) <= ~1M (entry, pixel) pairs: short chunks when many
tiles are active (less wasted work after pixels saturate), long ones when few are (fewer steps)."""
ALPHA_MAX = 0.99
T_MIN = 1e-4
PIX = TILE * TILE


@dataclass
class _Tiles:
    """The non-empty tiles: their list starts/lengths and pixel-centre coordinates (A, 64, 2)."""

    ids: torch.Tensor
    start: torch.Tensor
    count: torch.Tensor
    pixels: torch.Tensor


def _tiles(bins: TileBins, n_cams: int, width: int, height: int) -> _Tiles:
    tiles_x, tiles_y = tile_grid(width, height)
    offsets = bins.offsets.long()
    count = offsets[1:] - offsets[:-1]
    ids = (count > 0).nonzero().squeeze(1)
    local = ids % (tiles_x * tiles_y)
    origin = torch.stack([(local % tiles_x) * TILE, torch.div(local, tiles_x, rounding_mode="floor") * TILE], -1)
    r = torch.arange(TILE, device=ids.device)
    offs = torch.stack(torch.meshgrid(r, r, indexing="xy"), -1).reshape(PIX, 2)
    pixels = (origin[:, None, :] + offs[None]).float() + 0.5
    return _Tiles(ids=ids, start=offsets[:-1][ids], count=count[ids], pixels=pixels)


@dataclass
class _Chunk:
    """One depth chunk of the active tiles: entry ids, geometry terms and the effective alphas."""

    entries: torch.Tensor  # (A, K) entry index (0 where padded)
    dx: torch.Tensor       # (A, K, 64)
    dy: torch.Tensor
    gauss: torch.Tensor    # exp(power)
    raw: torch.Tensor      # opacity * exp(power)
    alpha: torch.Tensor    # effective alpha (0 = skipped or padded or pixel done)
    t_before: torch.Tensor  # transmittance in front of each entry
    t_after: torch.Tensor   # (A, 64) transmittance behind the chunk
    stop: torch.Tensor      # (A, 64) pixels that finished inside this chunk


def chunk_size(active_tiles: int) -> int:
    """Entries per tile in one step, from the number of active tiles (deterministic: forward and
    backward sweeps must cut their lists identically)."""
    return max(CHUNK_MIN, min(CHUNK_MAX, CHUNK_ELEMENTS // max(1, active_tiles * PIX)))


def _chunk(means2d, conics, opacities, pair_gauss, tiles: _Tiles, rows, j, size, t_run, done) -> _Chunk:
    k = torch.arange(size, device=rows.device)
    pos = j + k[None, :]
    inside = pos < tiles.count[rows, None]
    entries = torch.where(inside, pair_gauss[(tiles.start[rows, None] + pos).clamp(max=pair_gauss.numel() - 1)], 0)
    m, q, o = means2d[entries], conics[entries], opacities[entries]
    px = tiles.pixels[rows]
    dx = m[..., 0:1] - px[:, None, :, 0]
    dy = m[..., 1:2] - px[:, None, :, 1]
    power = -0.5 * (q[..., 0:1] * dx * dx + q[..., 2:3] * dy * dy) - q[..., 1:2] * dx * dy
    gauss = torch.exp(power)
    raw = o[..., None] * gauss
    live = inside[..., None] & (power <= 0) & (raw >= ALPHA_MIN) & ~done[:, None, :]
    alpha = torch.where(live, raw.clamp(max=ALPHA_MAX), 0.0)
    t_incl = t_run[:, None, :] * torch.cumprod(1.0 - alpha, dim=1)
    keep = t_incl >= T_MIN
    alpha = alpha * keep
    t_before = torch.cat([t_run[:, None, :], t_incl[:, :-1]], dim=1)
    t_after = t_run * torch.prod(1.0 - alpha, dim=1)
    stop = (~keep).any(dim=1)
    return _Chunk(entries, dx, dy, gauss, raw, alpha, t_before, t_after, stop)


def _sweep(tiles: _Tiles, fn) -> None:
    """Visit every active tile's list chunk by chunk; ``fn(rows, j, size)`` returns a (len(rows),) done mask."""
    rows = torch.arange(tiles.ids.numel(), device=tiles.ids.device)
    j = 0
    while rows.numel():
        size = chunk_size(rows.numel())
        finished = fn(rows, j, size)
        j += size
        rows = rows[~finished & (tiles.count[rows] > j)]


class _Composite(torch.autograd.Function):
    @staticmethod
    def forward(ctx, means2d, conics, colors, opacities, bins: TileBins, n_cams: int, width: int, height: int):
        tiles = _tiles(bins, n_cams, width, height)
        a, d = tiles.ids.numel(), colors.shape[1]
        acc = means2d.new_zeros(a, PIX, d)
        t_run = means2d.new_ones(a, PIX)
        done = torch.zeros(a, PIX, dtype=torch.bool, device=means2d.device)

        def step(rows, j, size):
            ch = _chunk(means2d, conics, opacities, bins.pair_gauss.long(), tiles, rows, j, size, t_run[rows], done[rows])
            acc[rows] += torch.einsum("akp,akc->apc", ch.alpha * ch.t_before, colors[ch.entries])
            t_run[rows] = ch.t_after
            done[rows] |= ch.stop
            return done[rows].all(dim=1)

        _sweep(tiles, step)
        ctx.save_for_backward(means2d, conics, colors, opacities, bins.offsets, bins.pair_gauss, acc, t_run)
        ctx.shape = (n_cams, width, height)
        return _to_image(acc, tiles, n_cams, width, height), _to_image(1.0 - t_run[..., None], tiles, n_cams, width, height)[..., 0]

    @staticmethod
    def backward(ctx, grad_image, grad_alpha):
        means2d, conics, colors, opacities, offsets, pairs, acc_final, t_final = ctx.saved_tensors
        n_cams, width, height = ctx.shape
        bins = TileBins(offsets=offsets, pair_gauss=pairs)
        tiles = _tiles(bins, n_cams, width, height)
        g_img = _from_image(grad_image, tiles, colors.shape[1], width, height) if grad_image is not None else None
        g_a = _from_image(grad_alpha[..., None], tiles, 1, width, height)[..., 0] if grad_alpha is not None else None
        if g_img is None:
            g_img = torch.zeros_like(acc_final)
        if g_a is None:
            g_a = torch.zeros_like(t_final)
        grads = torch.zeros(means2d.shape[0], 6 + colors.shape[1], dtype=means2d.dtype, device=means2d.device)
        g_total = (g_img * acc_final).sum(-1)      # g . C_final per pixel
        g_prefix = torch.zeros_like(t_final)       # g . (colour composited so far) per pixel
        t_run = torch.ones_like(t_final)
        done = torch.zeros_like(t_final, dtype=torch.bool)

        def step(rows, j, size):
            ch = _chunk(means2d, conics, opacities, pairs.long(), tiles, rows, j, size, t_run[rows], done[rows])
            g = g_img[rows]
            gc = torch.einsum("apc,akc->akp", g, colors[ch.entries])          # g . c_i per pixel
            w = ch.alpha * ch.t_before
            wgc = w * gc
            behind = g_total[rows][:, None] - g_prefix[rows][:, None] - torch.cumsum(wgc, dim=1)
            inv = 1.0 / (1.0 - ch.alpha)
            d_alpha = ch.t_before * gc - behind * inv + g_a[rows][:, None, :] * t_final[rows][:, None, :] * inv
            d_alpha = torch.where((ch.alpha > 0) & (ch.raw < ALPHA_MAX), d_alpha, 0.0)
            d_power = d_alpha * ch.alpha
            gx, gy = d_power * ch.dx, d_power * ch.dy
            sx, sy = gx.sum(-1), gy.sum(-1)
            q = conics[ch.entries]
            rec = torch.cat(
                [
                    torch.stack([
                        -(q[..., 0] * sx + q[..., 1] * sy),
                        -(q[..., 2] * sy + q[..., 1] * sx),
                        -0.5 * (gx * ch.dx).sum(-1),
                        -(gx * ch.dy).sum(-1),
                        -0.5 * (gy * ch.dy).sum(-1),
                        (d_alpha * ch.gauss).sum(-1),
                    ], dim=-1),
                    torch.einsum("akp,apc->akc", w, g),
                ],
                dim=-1,
            )
            grads.index_add_(0, ch.entries.reshape(-1), rec.reshape(-1, rec.shape[-1]))
            g_prefix[rows] += wgc.sum(dim=1)
            t_run[rows] = ch.t_after
            done[rows] |= ch.stop
            return done[rows].all(dim=1)

        _sweep(tiles, step)
        d = colors.shape[1]
        return grads[:, 0:2], grads[:, 2:5], grads[:, 6:6 + d], grads[:, 5], None, None, None, None


def _tile_view(img: torch.Tensor, width: int, height: int) -> torch.Tensor:
    """Pad an image batch (B,H,W,D) to whole tiles and view it as (B*tiles, 64, D)."""
    tiles_x, tiles_y = tile_grid(width, height)
    b, _, _, d = img.shape
    pad = img.new_zeros(b, tiles_y * TILE, tiles_x * TILE, d)
    pad[:, :height, :width] = img
    return pad.reshape(b, tiles_y, TILE, tiles_x, TILE, d).permute(0, 1, 3, 2, 4, 5).reshape(-1, PIX, d)


def _to_image(values: torch.Tensor, tiles: _Tiles, n_cams: int, width: int, height: int) -> torch.Tensor:
    """Scatter per-tile pixel values (A, 64, D) into images (B, H, W, D); empty tiles are 0."""
    tiles_x, tiles_y = tile_grid(width, height)
    d = values.shape[-1]
    flat = values.new_zeros(n_cams * tiles_x * tiles_y, PIX, d)
    flat[tiles.ids] = values
    img = flat.reshape(n_cams, tiles_y, tiles_x, TILE, TILE, d).permute(0, 1, 3, 2, 4, 5)
    return img.reshape(n_cams, tiles_y * TILE, tiles_x * TILE, d)[:, :height, :width].contiguous()


def _from_image(img: torch.Tensor, tiles: _Tiles, d: int, width: int, height: int) -> torch.Tensor:
    """Gather image values (B,H,W,D) into the active tiles' layout (A, 64, D)."""
    flat = _tile_view(img.reshape(img.shape[0], height, width, d), width, height)
    return flat[tiles.ids]


def composite(proj: Projection, n_cams: int, width: int, height: int) -> tuple[torch.Tensor, torch.Tensor]:
    """(image (B,H,W,D), alpha (B,H,W)) of the projected entries."""
    tiles_x, tiles_y = tile_grid(width, height)
    bins = bin_entries_torch(proj.tile_bbox, proj.cam_ids, proj.depths.detach(), n_cams, tiles_x, tiles_y)
    return _Composite.apply(proj.means2d, proj.conics, proj.colors, proj.opacities, bins, n_cams, width, height)
