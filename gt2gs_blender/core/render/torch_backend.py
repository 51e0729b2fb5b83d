"""The portable backend: compositing in plain torch (CPU or CUDA), all tiles at once, in depth chunks.

Each step takes the next chunk of entries of every still-active tile's list and composites them
for the tile's 64 pixels. A Gaussian's log-alpha over a tile is a quadratic in the pixel offset from
the tile centre, so one matrix product of per-slot coefficients (computed once per render, in
float64) with a fixed 6x64 basis gives every alpha of a chunk, and the backward reduces the power
gradients of a chunk with the transposed product. Pixels that reach T < 1e-4 are cut sparsely (few
per chunk). The backward recomputes the same chunks front to back (the colour behind an entry is
the final colour minus what was composited so far, both dotted with the pixel's colour gradient so
only scalars per pixel are kept), so memory stays bounded by one chunk instead of growing with the
number of (entry, pixel) pairs; chunk buffers are reused from chunk to chunk.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
import torch.nn.functional as F

from ..raster_rules import ALPHA_MAX, ALPHA_MIN, T_MIN, TILE
from .binning import TileBins, bin_entries_torch
from .projection import Projection, tile_grid

CHUNK_MIN = 16
CHUNK_MAX = 1024
CHUNK_ELEMENTS = 1 << 20
"""A step covers (active tiles x chunk x 64) <= ~1M (entry, pixel) pairs so its working set stays
in cache, but at least 16 entries per tile: per-step and per-tile costs outweigh list padding."""
PIX = TILE * TILE
LOG2E = 1.0 / math.log(2.0)
LOOP_MAX = 48
"""Longest chunk scanned with a loop of slice ops; longer ones use torch.cumprod/cumsum."""
PAD_LOG2 = -4096.0
"""log2-alpha of the padding slot: exp2 underflows to exactly 0 in float32 and float64."""


@dataclass
class _Lists:
    """Everything both sweeps read: the non-empty tiles' lists and per-slot coefficients and colours."""

    ids: torch.Tensor  # (A,) non-empty tiles
    start: torch.Tensor  # (A,) first slot of each tile's list
    count: torch.Tensor  # (A,) list lengths
    coefs: torch.Tensor  # (6, P + 1) log2-alpha coefficients over the basis; column P = padding
    colors: torch.Tensor  # (P + 1, D) colour of each slot; row P = padding
    basis: torch.Tensor  # (6, 64)
    pairs: torch.Tensor  # (P,) entry of each slot
    rel_means: torch.Tensor  # (2, P) each slot's 2D mean relative to its tile's centre
    clamp: bool  # some opacity can reach ALPHA_MAX
    alpha_cut: float  # alpha > alpha_cut  <=>  alpha >= ALPHA_MIN in this dtype

    @property
    def pad(self) -> int:
        """Index of the padding slot."""
        return self.colors.shape[0] - 1

    def split(self) -> tuple[tuple[torch.Tensor, ...], tuple[bool, float]]:
        """(tensor fields, other fields) in field order: the backward saves them apart."""
        tensors = (self.ids, self.start, self.count, self.coefs, self.colors, self.basis, self.pairs, self.rel_means)
        return tensors, (self.clamp, self.alpha_cut)


def _basis(dtype: torch.dtype, device: torch.device) -> torch.Tensor:
    """(6, 64) monomials 1, u, v, u^2, uv, v^2 of each pixel centre's offset (u, v) from its tile centre."""
    r = torch.arange(TILE, dtype=dtype, device=device) + (0.5 - TILE / 2)
    v, u = torch.meshgrid(r, r, indexing="ij")
    u, v = u.reshape(PIX), v.reshape(PIX)
    return torch.stack([torch.ones_like(u), u, v, u * u, u * v, v * v])


def _just_below(value: float, dtype: torch.dtype) -> float:
    """The largest number of ``dtype`` below ``value`` rounded to it, so x > result <=> x >= value."""
    v = torch.tensor(value, dtype=dtype)
    return torch.nextafter(v, torch.zeros_like(v)).item()


def _per_slot(values: torch.Tensor, pairs: torch.Tensor) -> list[torch.Tensor]:
    """Each column of per-entry ``values`` (M, C) for every list slot, detached: C tensors (P,).
    Gathering columns one by one is ~4x faster than a (P, C) or (C, P) gather for random entries."""
    return [column.index_select(0, pairs) for column in values.detach().t().contiguous()]


def _min_over_tile(
    xi: torch.Tensor,
    eta: torch.Tensor,
    a: torch.Tensor,
    b: torch.Tensor,
    c: torch.Tensor,
) -> torch.Tensor:
    """Smallest a dx^2 + 2b dx dy + c dy^2 over the square of pixel-centre offsets (dx, dy) =
    (xi - u, eta - v), |u|, |v| <= 3.5: 0 when it holds the centre, else the least of its 4 edges."""
    h = TILE / 2 - 0.5
    x_lo, x_hi, y_lo, y_hi = xi - h, xi + h, eta - h, eta + h
    best = torch.where((x_lo <= 0) & (x_hi >= 0) & (y_lo <= 0) & (y_hi >= 0), 0.0, math.inf)
    b2 = 2.0 * b
    # best y on each vertical edge and x on each horizontal one; a degenerate conic (a or c = 0, so
    # b = 0: a footprint infinitely long along an axis) is flat along that edge: any point will do
    slope_y = torch.where(c > 0, -b / torch.where(c > 0, c, 1.0), 0.0)
    slope_x = torch.where(a > 0, -b / torch.where(a > 0, a, 1.0), 0.0)
    edges = [(x, (slope_y * x).clamp_(y_lo, y_hi)) for x in (x_lo, x_hi)]
    edges += [((slope_x * y).clamp_(x_lo, x_hi), y) for y in (y_lo, y_hi)]
    for x, y in edges:
        best = torch.minimum(best, (a * x + b2 * y) * x + c * y * y)
    return best


def _lists(means2d, conics, colors, opacities, bins: TileBins, tiles_x: int, tiles_y: int) -> _Lists:
    """Tile lists and per-slot coefficients: log2 alpha = coefs . (1, u, v, u^2, uv, v^2).

    Slots whose Gaussian is below 1/255 at every pixel centre of the tile (the footprint box's
    corner tiles; ~15 % of them in random scenes) are dropped first: they composite nothing.
    The coefficients are formed in float64: far along a needle-like footprint the expansion
    cancels terms of ~1e6 (the float32 rounding left is that of a power of magnitude <~ 100)."""
    dtype, device = means2d.dtype, means2d.device
    f64 = torch.float64
    pairs = bins.pair_gauss.long()
    local = bins.pair_tile.long() % (tiles_x * tiles_y)
    row = torch.div(local, tiles_x, rounding_mode="floor")
    centre = torch.stack([local - row * tiles_x, row]).to(f64) * TILE + TILE / 2
    mx, my = _per_slot(means2d.to(f64), pairs)
    xi, eta = mx - centre[0], my - centre[1]
    a, b, c = _per_slot(conics.to(f64), pairs)
    log_o = torch.log(opacities.detach().to(f64)).index_select(0, pairs)
    # q <= 2 log(255 o) <=> alpha >= 1/255; the margin keeps every slot float rounding could light
    live = (_min_over_tile(xi, eta, a, b, c) <= 2.0 * (log_o - math.log(ALPHA_MIN)) + 1e-3).nonzero().squeeze(1)
    pairs, xi, eta, a, b, c, log_o = (t.index_select(-1, live) for t in (pairs, xi, eta, a, b, c, log_o))
    n_tiles = bins.offsets.numel() - 1
    count = torch.bincount(bins.pair_tile.index_select(0, live), minlength=n_tiles)
    cu = a * xi + b * eta
    cv = b * xi + c * eta
    c0 = log_o - 0.5 * (xi * cu + eta * cv)
    n = pairs.numel()
    coefs = torch.zeros(6, n + 1, dtype=dtype, device=device)
    for i, values in enumerate((c0, cu, cv, -0.5 * a, -b, -0.5 * c)):
        coefs[i, :n] = values * LOG2E
    coefs[0, n] = PAD_LOG2
    slot_colors = colors.new_zeros(n + 1, colors.shape[1])
    torch.index_select(colors.detach(), 0, pairs, out=slot_colors[:n])
    ids = (count > 0).nonzero().squeeze(1)
    start = torch.cumsum(count, 0) - count
    return _Lists(
        ids=ids,
        start=start[ids],
        count=count[ids],
        coefs=coefs,
        colors=slot_colors,
        basis=_basis(dtype, device),
        pairs=pairs,
        rel_means=torch.stack([xi, eta]).to(dtype),
        clamp=bool(opacities.numel()) and bool(opacities.detach().max() >= ALPHA_MAX * (1 - 1e-4)),
        alpha_cut=_just_below(ALPHA_MIN, dtype),
    )


class _Workspace:
    """Flat buffers reused by every chunk of a sweep: fresh multi-MiB tensors for every chunk are
    page-faulted in again each time (system time was a fifth of the CPU time before)."""

    def __init__(self, like: torch.Tensor) -> None:
        self.like = like
        self.buffers: dict[str, torch.Tensor] = {}

    def get(self, name: str, *shape: int) -> torch.Tensor:
        """An uninitialised view of ``shape`` on buffer ``name``, grown when too small."""
        n = math.prod(shape)
        buf = self.buffers.get(name)
        if buf is None or buf.numel() < n:
            buf = self.buffers[name] = self.like.new_empty(n)
        return buf[:n].view(shape)


@dataclass
class _Chunk:
    """One depth chunk of the active tiles, entries along dim 1, pixels along dim 2."""

    slots: torch.Tensor  # (A*K,) list slot of each entry (the padding slot past a list's end)
    alpha: torch.Tensor  # (A, K, 64) alpha; 0 below 1/255, when padded, and from a pixel's stop on
    one_minus: torch.Tensor  # (A, K, 64) 1 - alpha before the stop cut (only met by zero alphas after it)
    weight: torch.Tensor  # (A, K, 64) alpha * transmittance in front (0 for done pixels)
    t_after: torch.Tensor  # (A, 64) transmittance behind the chunk (unchanged for done pixels)
    done: torch.Tensor  # (A, 64) pixels finished by the end of the chunk


def chunk_size(active_tiles: int) -> int:
    """Entries per tile in one step, from the number of active tiles (deterministic: forward and
    backward sweeps must cut their lists identically)."""
    return max(CHUNK_MIN, min(CHUNK_MAX, CHUNK_ELEMENTS // max(1, active_tiles * PIX)))


def _transmittance(one_minus: torch.Tensor, trans: torch.Tensor, scratch: torch.Tensor) -> None:
    """trans[:, k + 1] = trans[:, k] * one_minus[:, k], given trans[:, 0]: a loop of slice ops for
    short chunks (several times faster than torch.cumprod there), torch.cumprod for long ones."""
    size = one_minus.shape[1]
    if size > LOOP_MAX:
        torch.mul(torch.cumprod(one_minus, 1, out=scratch), trans[:, :1], out=trans[:, 1:])
        return
    for k in range(size):
        torch.mul(trans[:, k], one_minus[:, k], out=trans[:, k + 1])


def _cumsum(x: torch.Tensor, seed: torch.Tensor, out: torch.Tensor) -> None:
    """out[:, k] = seed + x[:, 0] + ... + x[:, k], looped like ``_transmittance``."""
    size = x.shape[1]
    if size > LOOP_MAX:
        torch.cumsum(x, 1, out=out).add_(seed[:, None])
        return
    torch.add(seed, x[:, 0], out=out[:, 0])
    for k in range(1, size):
        torch.add(out[:, k - 1], x[:, k], out=out[:, k])


def _chunk(
    lists: _Lists, ws: _Workspace, rows: torch.Tensor, j: int, size: int, t_run: torch.Tensor, done: torch.Tensor
) -> _Chunk:
    """Alphas, transmittances and weights of entries j..j+size of the tiles ``rows``."""
    n = rows.numel()
    pos = j + torch.arange(size, device=rows.device)
    count, start = lists.count.index_select(0, rows), lists.start.index_select(0, rows)
    slots = torch.where(pos < count[:, None], start[:, None] + pos, lists.pad).reshape(-1)
    alpha = ws.get("alpha", n, size, PIX)
    torch.mm(lists.coefs.index_select(1, slots).t(), lists.basis, out=alpha.view(-1, PIX)).exp2_()
    if lists.clamp:
        alpha.clamp_max_(ALPHA_MAX)
    F.threshold_(alpha, lists.alpha_cut, 0.0)
    one_minus = torch.sub(alpha.new_ones(()), alpha, out=ws.get("one_minus", n, size, PIX))
    trans = ws.get("trans", n, size + 1, PIX)  # trans[:, k]: transmittance in front of entry k
    trans[:, 0].copy_(t_run).masked_fill_(done, 0.0)
    weight = ws.get("weight", n, size, PIX)
    _transmittance(one_minus, trans, weight)
    t_after = torch.where(done, t_run, trans[:, size])
    stopping = t_after < T_MIN
    stops = stopping.nonzero(as_tuple=True)
    if stops[0].numel():
        # Pixels that stop here: drop the entry that crosses T_MIN and all behind it; what is left
        # behind the chunk is the smallest transmittance still >= T_MIN. Few pixels, done sparsely.
        a, p = stops
        t = trans[a, :, p]
        keep = t[:, 1:] >= T_MIN
        alpha[a, :, p] = alpha[a, :, p] * keep
        t_after[a, p] = torch.where(keep, t[:, 1:], t[:, :1]).amin(dim=1)
    torch.mul(alpha, trans[:, :size], out=weight)
    return _Chunk(slots=slots, alpha=alpha, one_minus=one_minus, weight=weight, t_after=t_after, done=done | stopping)


def _sweep(lists: _Lists, fn) -> None:
    """Visit every active tile's list chunk by chunk; ``fn(rows, j, size)`` returns a (len(rows),) done mask."""
    rows = torch.arange(lists.ids.numel(), device=lists.ids.device)
    j = 0
    while rows.numel():
        size = chunk_size(rows.numel())
        finished = fn(rows, j, size)
        j += size
        rows = rows[~finished & (lists.count.index_select(0, rows) > j)]


class _Composite(torch.autograd.Function):
    @staticmethod
    def forward(ctx, means2d, conics, colors, opacities, bins: TileBins, n_cams: int, width: int, height: int):
        tiles_x, tiles_y = tile_grid(width, height)
        lists = _lists(means2d, conics, colors, opacities, bins, tiles_x, tiles_y)
        a, d = lists.ids.numel(), colors.shape[1]
        acc = means2d.new_zeros(a, d, PIX)
        t_run = means2d.new_ones(a, PIX)
        done = torch.zeros(a, PIX, dtype=torch.bool, device=means2d.device)
        ws = _Workspace(means2d.detach())

        def step(rows, j, size):
            ch = _chunk(lists, ws, rows, j, size, t_run.index_select(0, rows), done.index_select(0, rows))
            slot_colors = lists.colors.index_select(0, ch.slots).view(rows.numel(), size, d)
            acc.index_add_(0, rows, torch.bmm(slot_colors.transpose(1, 2), ch.weight))
            t_run.index_copy_(0, rows, ch.t_after)
            done.index_copy_(0, rows, ch.done)
            return ch.done.all(dim=1)

        _sweep(lists, step)
        list_tensors, ctx.list_flags = lists.split()
        ctx.save_for_backward(conics, opacities, acc, t_run, *list_tensors)
        ctx.shape = (width, height, means2d.shape[0])
        image = _to_image(acc.transpose(1, 2), lists.ids, n_cams, width, height)
        return image, _to_image(1.0 - t_run[..., None], lists.ids, n_cams, width, height)[..., 0]

    @staticmethod
    def backward(ctx, grad_image, grad_alpha):
        conics, opacities, acc_final, t_final, *list_tensors = ctx.saved_tensors
        lists = _Lists(*list_tensors, *ctx.list_flags)
        width, height, n_entries = ctx.shape
        d = lists.colors.shape[1]
        if grad_image is None:
            g_img = torch.zeros_like(acc_final)
        else:
            g_img = _from_image(grad_image, lists.ids, d, width, height).transpose(1, 2).contiguous()
        # per pixel: g . (colour behind the entries swept so far) - g_alpha * T_final
        remaining = (g_img * acc_final).sum(1)
        if grad_alpha is not None:
            remaining -= _from_image(grad_alpha[..., None], lists.ids, 1, width, height)[..., 0] * t_final
        slot_grads = acc_final.new_zeros(6 + d, lists.pad + 1)
        t_run = torch.ones_like(t_final)
        done = torch.zeros_like(t_final, dtype=torch.bool)
        ws = _Workspace(acc_final)

        def step(rows, j, size):
            done_rows = done.index_select(0, rows)
            ch = _chunk(lists, ws, rows, j, size, t_run.index_select(0, rows), done_rows)
            g = g_img.index_select(0, rows)
            slot_colors = lists.colors.index_select(0, ch.slots).view(rows.numel(), size, d)
            wgc = torch.bmm(slot_colors, g, out=ws.get("wgc", rows.numel(), size, PIX)).mul_(ch.weight)
            # dL/dpower_k = alpha_k T_k g.c_k - alpha_k / (1 - alpha_k) (g . colour behind k - g_alpha T_final)
            # where (g . colour behind k - g_alpha T_final) = rest - (wgc_0 + ... + wgc_k) = -behind[:, k];
            # done pixels get 0 (rest = 0 and zero weights: their alphas are not cut).
            rest = remaining.index_select(0, rows).masked_fill_(done_rows, 0.0)
            behind = ws.get("behind", rows.numel(), size, PIX)
            _cumsum(wgc, rest.neg_(), behind)
            remaining.index_copy_(0, rows, behind[:, -1].neg())
            d_power = wgc.addcmul_(torch.div(ch.alpha, ch.one_minus, out=ch.one_minus), behind)
            if lists.clamp:
                d_power.masked_fill_(ch.alpha >= ALPHA_MAX, 0.0)
            slot_grads[:6].index_copy_(1, ch.slots, torch.mm(lists.basis, d_power.view(-1, PIX).t()))
            d_color = torch.bmm(ch.weight, g.transpose(1, 2)).view(-1, d)
            slot_grads[6:].index_copy_(1, ch.slots, d_color.t())
            t_run.index_copy_(0, rows, ch.t_after)
            done.index_copy_(0, rows, ch.done)
            return ch.done.all(dim=1)

        _sweep(lists, step)
        grads = _entry_grads(conics, opacities, lists.pairs, lists.rel_means, slot_grads[:, :-1], n_entries)
        return grads[0:2].t(), grads[2:5].t(), grads[6:].t(), grads[5], None, None, None, None


def _entry_grads(conics, opacities, pairs, rel_means, slot_grads, n_entries: int) -> torch.Tensor:
    """Chain the per-slot coefficient and colour gradients (6 + D, P) to the entries: (6 + D, M) rows
    d means2d (2), d conics (3), d opacity, d colour (D)."""
    s0, su, sv, suu, suv, svv = slot_grads[:6]
    xi, eta = rel_means
    a, b, c = _per_slot(conics, pairs)
    cu = a * xi + b * eta
    cv = b * xi + c * eta
    grads = slot_grads.new_zeros(slot_grads.shape[0], n_entries)
    grads[:6].index_add_(
        1,
        pairs,
        torch.stack(
            [
                a * su + b * sv - cu * s0,
                b * su + c * sv - cv * s0,
                xi * su - 0.5 * (xi * xi * s0 + suu),
                eta * su + xi * sv - xi * eta * s0 - suv,
                eta * sv - 0.5 * (eta * eta * s0 + svv),
                s0 / opacities.detach().index_select(0, pairs),
            ]
        ),
    )
    grads[6:].index_add_(1, pairs, slot_grads[6:])
    return grads


def _to_image(values: torch.Tensor, ids: torch.Tensor, n_cams: int, width: int, height: int) -> torch.Tensor:
    """Scatter per-tile pixel values (A, 64, D) into images (B, H, W, D); empty tiles are 0."""
    tiles_x, tiles_y = tile_grid(width, height)
    d = values.shape[-1]
    flat = values.new_zeros(n_cams * tiles_x * tiles_y, PIX, d)
    flat[ids] = values
    img = flat.reshape(n_cams, tiles_y, tiles_x, TILE, TILE, d).permute(0, 1, 3, 2, 4, 5)
    return img.reshape(n_cams, tiles_y * TILE, tiles_x * TILE, d)[:, :height, :width].contiguous()


def _from_image(img: torch.Tensor, ids: torch.Tensor, d: int, width: int, height: int) -> torch.Tensor:
    """Gather image values (B,H,W,D) into the non-empty tiles' layout (A, 64, D)."""
    tiles_x, tiles_y = tile_grid(width, height)
    b = img.shape[0]
    pad = img.new_zeros(b, tiles_y * TILE, tiles_x * TILE, d)
    pad[:, :height, :width] = img.reshape(b, height, width, d)
    return pad.reshape(b, tiles_y, TILE, tiles_x, TILE, d).permute(0, 1, 3, 2, 4, 5).reshape(-1, PIX, d)[ids]


def composite(proj: Projection, n_cams: int, width: int, height: int) -> tuple[torch.Tensor, torch.Tensor]:
    """(image (B,H,W,D), alpha (B,H,W)) of the projected entries."""
    tiles_x, tiles_y = tile_grid(width, height)
    bins = bin_entries_torch(proj.tile_bbox, proj.cam_ids, proj.depths.detach(), n_cams, tiles_x, tiles_y)
    return _Composite.apply(proj.means2d, proj.conics, proj.colors, proj.opacities, bins, n_cams, width, height)
