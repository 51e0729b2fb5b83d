"""The compiled CPU kernel (csrc/) ported to numba: the same functions, arguments and results, with no C++ compiler.

Each function mirrors the one of the same name in ``csrc/raster_cpu.cpp`` or ``csrc/project_cpu.cpp``
(read their comments for the mathematics): the projection in double, the depth radix sort, the tile
binning, the compositing sweeps over 8x8 tiles (forward, backward, recorded weights) and the weighted
gather/scatter of colour-only redraws. Loops over tiles run in parallel (``prange``) over a fixed
number of work units, each with its own scratch and gradient buffers, so results do not depend on
thread timing. The sweeps compute in the inputs' dtype: constants come from a small array of that
dtype (``_constants``), never from Python float literals, which numba would widen to float64.
Compiled on first use and cached on disk (``cache=True``, under ``NUMBA_CACHE_DIR``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ..raster_rules import ALPHA_MAX, ALPHA_MIN, EPS2D, FOV_CLAMP, T_MIN, TILE
from ..rotations import rotation_entries
from ..scene.inria import SH_C0, SH_C1, SH_C2, SH_C3

UNITS_PER_THREAD = 8
"""Forward work units per thread: tiles are dealt round-robin to units, which balances busy image centres."""
JIT = {"cache": True, "nogil": True, "error_model": "numpy"}
# index of each constant in _constants(dtype)
_HALF, _ONE, _ALPHA_MAX, _T_MIN, _ZERO = 0, 1, 2, 3, 4


def _constants(dtype: np.dtype) -> np.ndarray:
    """The sweeps' constants in the kernel's dtype (0.5, 1, alpha max, transmittance min, 0)."""
    return np.array([0.5, 1.0, ALPHA_MAX, T_MIN, 0.0], dtype=dtype)


# ---------------------------------------------------------------------------------------------- sorting


@njit(**JIT)
def depth_order(depths: np.ndarray) -> np.ndarray:
    """Entry indices front to back, ties by index: a stable LSD radix sort of the float32 bits (3 x 11 bits)."""
    m = depths.shape[0]
    bits = depths.view(np.uint32)
    keys = np.empty(m, np.uint32)
    idx = np.empty(m, np.int64)
    count = np.zeros((3, 2048), np.int64)
    for i in range(m):
        b = bits[i]
        if b == np.uint32(0x80000000):
            b = np.uint32(0)
        k = ~b if b & np.uint32(0x80000000) else b | np.uint32(0x80000000)
        keys[i] = k
        idx[i] = i
        for p in range(3):
            count[p, (k >> np.uint32(11 * p)) & np.uint32(2047)] += 1
    keys_tmp = np.empty(m, np.uint32)
    idx_tmp = np.empty(m, np.int64)
    for p in range(3):
        total = 0
        for d in range(2048):
            n = count[p, d]
            count[p, d] = total
            total += n
        shift = np.uint32(11 * p)
        for i in range(m):
            digit = (keys[i] >> shift) & np.uint32(2047)
            slot = count[p, digit]
            count[p, digit] = slot + 1
            keys_tmp[slot] = keys[i]
            idx_tmp[slot] = idx[i]
        keys, keys_tmp = keys_tmp, keys
        idx, idx_tmp = idx_tmp, idx
    return idx


@njit(parallel=True, **JIT)
def bin_tiles(tile_bbox, cam_ids, order, n_cams, tiles_x, tiles_y, runs):
    """(tile offsets (n_tiles+1,) int32, pair entries (P,) int32): entries per tile, front to back.

    ``runs`` contiguous runs of the depth order count, then scatter, in parallel; a tile's slots are
    handed out run by run, so the lists are the serial counting sort's."""
    m = tile_bbox.shape[0]
    tiles_per_cam = tiles_x * tiles_y
    n_tiles = n_cams * tiles_per_cam
    slots = np.zeros((runs, n_tiles), np.int64)
    for r in prange(runs):
        for j in range(m * r // runs, m * (r + 1) // runs):
            i = order[j]
            base = cam_ids[i] * tiles_per_cam
            for ty in range(tile_bbox[i, 1], tile_bbox[i, 3] + 1):
                for tx in range(tile_bbox[i, 0], tile_bbox[i, 2] + 1):
                    slots[r, base + ty * tiles_x + tx] += 1
    offsets = np.empty(n_tiles + 1, np.int32)
    total = 0
    for t in range(n_tiles):
        offsets[t] = total
        for r in range(runs):
            n = slots[r, t]
            slots[r, t] = total
            total += n
        if total >= 2147483647:
            raise ValueError("too many Gaussian/tile pairs for one render; render fewer cameras at once")
    offsets[n_tiles] = total
    pairs = np.empty(total, np.int32)
    for r in prange(runs):
        for j in range(m * r // runs, m * (r + 1) // runs):
            i = order[j]
            base = cam_ids[i] * tiles_per_cam
            for ty in range(tile_bbox[i, 1], tile_bbox[i, 3] + 1):
                for tx in range(tile_bbox[i, 0], tile_bbox[i, 2] + 1):
                    t = base + ty * tiles_x + tx
                    pairs[slots[r, t]] = i
                    slots[r, t] += 1
    return offsets, pairs


# ------------------------------------------------------------------------------------------ compositing


@njit(parallel=True, **JIT)
def footprints(conics, opacities):
    """Per entry: log_min = -log(255 o) (power below which alpha < 1/255) and the half height of the
    alpha >= 1/255 ellipse (padded by 1e-2 px; infinite for a degenerate conic)."""
    m = opacities.shape[0]
    log_min = np.empty(m, opacities.dtype)
    half = np.empty(m, np.float64)
    for g in prange(m):
        a, b, c = conics[g, 0], conics[g, 1], conics[g, 2]
        lm = -math.log(255.0 * opacities[g])
        det = a * c - b * b
        r2 = -2.0 * lm
        log_min[g] = lm
        half[g] = math.sqrt(r2 * a / det) + 1e-2 if det > 0 and r2 >= 0 else math.inf
    return log_min, half


@njit(**JIT)
def _row_range(centre, half, origin, last):
    """Rows [lo, hi] of a tile (clipped to [0, last]) whose pixel centres lie within ``half`` of ``centre``."""
    if not (half < 1e6) or not (abs(centre) < 1e6):
        return 0, last
    first = math.ceil(centre - half - 0.5) - origin
    final = math.floor(centre + half - 0.5) - origin
    lo = int(min(first, last + 1)) if first > 0 else 0
    hi = int(max(final, -1)) if final < last else last
    return lo, hi


@njit(**JIT)
def _tile_origin(tile, tiles_x, tiles_y, width, height):
    """(camera, x0, y0, last column, last row) of a tile."""
    per_cam = tiles_x * tiles_y
    cam = tile // per_cam
    x0 = (tile % per_cam % tiles_x) * TILE
    y0 = (tile % per_cam // tiles_x) * TILE
    return cam, x0, y0, min(TILE, width - x0) - 1, min(TILE, height - y0) - 1


@njit(**JIT)
def _gather(m2, cn, op, log_min, half, pg, begin, end, y0, last_y, sp, rows):
    """The tile's splats into the unit's scratch: sp[j] = (mx, my, a, b, c, opacity, log_min), rows[j] = (lo, hi)."""
    for k in range(begin, end):
        g = pg[k]
        j = k - begin
        sp[j, 0] = m2[g, 0]
        sp[j, 1] = m2[g, 1]
        sp[j, 2] = cn[g, 0]
        sp[j, 3] = cn[g, 1]
        sp[j, 4] = cn[g, 2]
        sp[j, 5] = op[g]
        sp[j, 6] = log_min[g]
        rows[j, 0], rows[j, 1] = _row_range(m2[g, 1], half[g], y0, last_y)


@njit(parallel=True, **JIT)
def sweep(
    m2,
    cn,
    op,
    col,
    off,
    pg,
    foot,
    units,
    n_cams,
    width,
    height,
    consts,
    mode,
    out_color,
    out_t,
    out_end,
    row_ptr,
    ent,
    wts,
):
    """The front-to-back sweep of forward() and contributions(): per tile, per splat in depth order, the
    weight w = alpha T of each still-compositing pixel. Mode 0 sums w * colour into ``out_color``; mode 1
    counts each pixel's weights into ``row_ptr[pixel + 1]``; mode 2 writes them (entry, weight) at the
    cursor ``row_ptr[pixel]``. Writes each pixel's final transmittance and one past its last used pair.
    ``foot``: footprints() of the entries; ``units``: parallel work units, each dealt every units-th tile."""
    tiles_x = (width + TILE - 1) // TILE
    tiles_y = (height + TILE - 1) // TILE
    n_tiles = n_cams * tiles_x * tiles_y
    n_ch = col.shape[1]
    log_min, half = foot
    longest = 0
    for t in range(n_tiles):
        longest = max(longest, off[t + 1] - off[t])
    one, zero, amax, tmin, hlf = consts[_ONE], consts[_ZERO], consts[_ALPHA_MAX], consts[_T_MIN], consts[_HALF]
    for u in prange(units):
        sp = np.empty((longest, 7), m2.dtype)
        rows = np.empty((longest, 2), np.int64)
        trans = np.empty((TILE, TILE), m2.dtype)
        last = np.empty((TILE, TILE), np.int64)
        live = np.empty((TILE, TILE), np.bool_)
        row_live = np.empty(TILE, np.bool_)
        acc = np.empty((TILE, TILE, n_ch), m2.dtype)
        fx = np.empty(TILE, m2.dtype)
        fy = np.empty(TILE, m2.dtype)
        for tile in range(u, n_tiles, units):
            begin, end = off[tile], off[tile + 1]
            if begin == end:
                continue
            cam, x0, y0, last_x, last_y = _tile_origin(tile, tiles_x, tiles_y, width, height)
            _gather(m2, cn, op, log_min, half, pg, begin, end, y0, last_y, sp, rows)
            _pixel_centres(x0, y0, hlf, fx, fy)
            rows_live = last_y + 1
            for r in range(TILE):
                row_live[r] = r <= last_y
                for lane in range(TILE):
                    trans[r, lane] = one
                    last[r, lane] = begin
                    live[r, lane] = lane <= last_x
                    for ch in range(n_ch):
                        acc[r, lane, ch] = zero
            k = begin
            while k < end and rows_live > 0:
                j = k - begin
                mx, my, a, b, c, o, lm = sp[j, 0], sp[j, 1], sp[j, 2], sp[j, 3], sp[j, 4], sp[j, 5], sp[j, 6]
                entry = pg[k]
                for r in range(rows[j, 0], rows[j, 1] + 1):
                    if not row_live[r]:
                        continue
                    dy = my - fy[r]
                    any_live = False
                    for lane in range(TILE):
                        if not live[r, lane]:
                            continue
                        dx = mx - fx[lane]
                        power = -hlf * (a * dx * dx + c * dy * dy) - b * dx * dy
                        if power <= zero and power >= lm:
                            alpha = min(o * math.exp(power), amax)
                            t = trans[r, lane]
                            next_t = t * (one - alpha)
                            if next_t < tmin:
                                live[r, lane] = False
                                continue
                            w = alpha * t
                            if mode == 0:
                                for ch in range(n_ch):
                                    acc[r, lane, ch] += w * col[entry, ch]
                            else:
                                pix = (cam * height + y0 + r) * width + x0 + lane
                                if mode == 1:
                                    row_ptr[pix + 1] += 1
                                else:
                                    slot = row_ptr[pix]
                                    ent[slot] = entry
                                    wts[slot] = w
                                    row_ptr[pix] = slot + 1
                            trans[r, lane] = next_t
                            last[r, lane] = k + 1
                        any_live = True
                    if not any_live:
                        row_live[r] = False
                        rows_live -= 1
                k += 1
            for r in range(last_y + 1):
                for lane in range(last_x + 1):
                    pix = (cam * height + y0 + r) * width + x0 + lane
                    out_t[pix] = trans[r, lane]
                    out_end[pix] = last[r, lane]
                    if mode == 0:
                        for ch in range(n_ch):
                            out_color[pix, ch] = acc[r, lane, ch]


@njit(parallel=True, **JIT)
def backward(
    m2,
    cn,
    col,
    op,
    off,
    pg,
    foot,
    units,
    final_t,
    pixel_end,
    grad_color,
    grad_alpha,
    n_cams,
    width,
    height,
    consts,
    geom,
):
    """Gradient records (M, 6 + C) of forward(): mx, my, conic a, b, c, opacity, colours (without ``geom``
    only the colours'). Each pixel's list is walked back to front, its transmittance recovered by division;
    each of the ``units`` owns fixed tiles and a gradient buffer, summed at the end: reproducible."""
    tiles_x = (width + TILE - 1) // TILE
    tiles_y = (height + TILE - 1) // TILE
    n_tiles = n_cams * tiles_x * tiles_y
    n_ch = col.shape[1]
    m = m2.shape[0]
    stride = 6 + n_ch
    log_min, half = foot
    longest = 0
    for t in range(n_tiles):
        longest = max(longest, off[t + 1] - off[t])
    buffers = np.zeros((units, m, stride), m2.dtype)
    one, zero, amax, hlf = consts[_ONE], consts[_ZERO], consts[_ALPHA_MAX], consts[_HALF]
    n_pairs = (n_tiles + 1) // 2
    for u in prange(units):
        mine = buffers[u]
        sp = np.empty((longest, 7), m2.dtype)
        rows = np.empty((longest, 2), np.int64)
        trans = np.empty((TILE, TILE), m2.dtype)
        t_final = np.empty((TILE, TILE), m2.dtype)
        g_alpha = np.empty((TILE, TILE), m2.dtype)
        stop = np.empty((TILE, TILE), np.int64)
        row_end = np.empty(TILE, np.int64)
        grad = np.empty((TILE, TILE, n_ch), m2.dtype)
        behind = np.empty((TILE, TILE, n_ch), m2.dtype)
        rec = np.empty(stride, m2.dtype)
        fx = np.empty(TILE, m2.dtype)
        fy = np.empty(TILE, m2.dtype)
        for pair in range(u, n_pairs, units):  # tiles dealt two at a time, as the C++ kernel's schedule(static, 2)
            for tile in range(2 * pair, min(2 * pair + 2, n_tiles)):
                begin, end = off[tile], off[tile + 1]
                if begin == end:
                    continue
                cam, x0, y0, last_x, last_y = _tile_origin(tile, tiles_x, tiles_y, width, height)
                _gather(m2, cn, op, log_min, half, pg, begin, end, y0, last_y, sp, rows)
                _pixel_centres(x0, y0, hlf, fx, fy)
                last = begin
                for r in range(TILE):
                    row_end[r] = begin
                    for lane in range(TILE):
                        stop[r, lane] = begin
                        for ch in range(n_ch):
                            grad[r, lane, ch] = zero
                            behind[r, lane, ch] = zero
                    if r > last_y:
                        continue
                    for lane in range(last_x + 1):
                        pix = (cam * height + y0 + r) * width + x0 + lane
                        trans[r, lane] = final_t[pix]
                        t_final[r, lane] = final_t[pix]
                        g_alpha[r, lane] = grad_alpha[pix]
                        stop[r, lane] = pixel_end[pix]
                        row_end[r] = max(row_end[r], pixel_end[pix])
                        for ch in range(n_ch):
                            grad[r, lane, ch] = grad_color[pix, ch]
                    last = max(last, row_end[r])
                for k in range(last - 1, begin - 1, -1):
                    j = k - begin
                    mx, my, a, b, c, o, lm = sp[j, 0], sp[j, 1], sp[j, 2], sp[j, 3], sp[j, 4], sp[j, 5], sp[j, 6]
                    entry = pg[k]
                    touched = False
                    for r in range(rows[j, 0], rows[j, 1] + 1):
                        if k >= row_end[r]:
                            continue
                        dy = my - fy[r]
                        for lane in range(last_x + 1):
                            if k >= stop[r, lane]:
                                continue
                            dx = mx - fx[lane]
                            power = -hlf * (a * dx * dx + c * dy * dy) - b * dx * dy
                            if not (power <= zero and power >= lm):
                                continue
                            if not touched:
                                for i in range(stride):
                                    rec[i] = zero
                                touched = True
                            gauss = math.exp(power)
                            raw = o * gauss
                            alpha = min(raw, amax)
                            inv = one / (one - alpha)
                            t = trans[r, lane] * inv
                            trans[r, lane] = t
                            w = alpha * t
                            if not geom:
                                for ch in range(n_ch):
                                    rec[6 + ch] += w * grad[r, lane, ch]
                                continue
                            d_alpha = g_alpha[r, lane] * t_final[r, lane] * inv
                            for ch in range(n_ch):
                                g = grad[r, lane, ch]
                                cc = col[entry, ch]
                                rec[6 + ch] += w * g
                                d_alpha += g * (t * cc - behind[r, lane, ch] * inv)
                                behind[r, lane, ch] += w * cc
                            if raw < amax:  # clamped: alpha ignores the parameters
                                d_power = d_alpha * alpha
                                rec[0] -= d_power * (a * dx + b * dy)
                                rec[1] -= d_power * (c * dy + b * dx)
                                rec[2] -= hlf * d_power * dx * dx
                                rec[3] -= d_power * dx * dy
                                rec[4] -= hlf * d_power * dy * dy
                                rec[5] += d_alpha * gauss
                    if touched:
                        for i in range(0 if geom else 6, stride):
                            mine[entry, i] += rec[i]
    total = buffers[0].copy()
    for u in range(1, units):
        total += buffers[u]
    return total


@njit(parallel=True, **JIT)
def weighted_rows(row, ent, w, values, out):
    """out[p] = sum over row p of weights * values[entries] (the forward sweep's sums, in its order)."""
    n_ch = values.shape[1]
    for p in prange(row.shape[0] - 1):
        for ch in range(n_ch):
            out[p, ch] = 0
        for k in range(row[p], row[p + 1]):
            e = ent[k]
            for ch in range(n_ch):
                out[p, ch] += w[k] * values[e, ch]


@njit(parallel=True, **JIT)
def weighted_rows_backward(row, ent, w, grad, n_values, units):
    """grad_values[e] = sum of weight * grad[row] over e's contributions: sums over ``units`` fixed row
    ranges, then added (reproducible)."""
    rows = row.shape[0] - 1
    n_ch = grad.shape[1]
    buffers = np.zeros((units, n_values, n_ch), grad.dtype)
    for u in prange(units):
        mine = buffers[u]
        for p in range(rows * u // units, rows * (u + 1) // units):
            for k in range(row[p], row[p + 1]):
                e = ent[k]
                for ch in range(n_ch):
                    mine[e, ch] += w[k] * grad[p, ch]
    total = buffers[0].copy()
    for u in range(1, units):
        total += buffers[u]
    return total


# ------------------------------------------------------------------------------------------- projection


@njit(**JIT)
def _camera(viewmat, k, width, height):
    """(R (3,3), t (3,), fx, fy, cx, cy, centre (3,), frustum limits x+, x-, y+, y-) of one camera, in double."""
    r = np.empty((3, 3))
    t = np.empty(3)
    for i in range(3):
        for j in range(3):
            r[i, j] = viewmat[i, j]
        t[i] = viewmat[i, 3]
    centre = np.empty(3)
    for j in range(3):
        centre[j] = -(r[0, j] * t[0] + r[1, j] * t[1] + r[2, j] * t[2])
    fx, fy, cx, cy = np.float64(k[0, 0]), np.float64(k[1, 1]), np.float64(k[0, 2]), np.float64(k[1, 2])
    pad_x = (FOV_CLAMP - 1.0) * 0.5 * width / fx
    pad_y = (FOV_CLAMP - 1.0) * 0.5 * height / fy
    lims = ((width - cx) / fx + pad_x, cx / fx + pad_x, (height - cy) / fy + pad_y, cy / fy + pad_y)
    return r, t, fx, fy, cx, cy, centre, lims


_rotation_entries = njit(**JIT)(rotation_entries)


@njit(**JIT)
def _pixel_centres(x0, y0, hlf, fx, fy):
    """A tile's pixel centres along x and y into ``fx``/``fy`` (the integer, then the half added in the buffer's
    float type, as the C++ kernel rounds them)."""
    for i in range(TILE):
        fx[i] = x0 + i
        fx[i] += hlf
        fy[i] = y0 + i
        fy[i] += hlf


@njit(**JIT)
def _rotation(qw, qx, qy, qz):
    """(normalised quaternion (4-tuple), its norm, whether it is non-zero, rotation matrix (9-tuple))."""
    norm = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
    ok = norm > 1e-12
    if ok:
        w, x, y, z = qw / norm, qx / norm, qy / norm, qz / norm
    else:
        w, x, y, z = 1.0, 0.0, 0.0, 0.0
    return (w, x, y, z), norm, ok, _rotation_entries(w, x, y, z)


@njit(**JIT)
def _geometry(r, t, fx, fy, lims, mean, quat, scale, g):
    """One (camera, Gaussian) pair's projection chain into the scratch ``g`` (see _G_* slots); returns
    (x, y, z, clamp_x, clamp_y, quaternion ok, normalised quaternion, its norm, rotation)."""
    x = r[0, 0] * mean[0] + r[0, 1] * mean[1] + r[0, 2] * mean[2] + t[0]
    y = r[1, 0] * mean[0] + r[1, 1] * mean[1] + r[1, 2] * mean[2] + t[1]
    z = r[2, 0] * mean[0] + r[2, 1] * mean[1] + r[2, 2] * mean[2] + t[2]
    rx, ry = x / z, y / z
    cx = min(max(rx, -lims[1]), lims[0])
    cy = min(max(ry, -lims[3]), lims[2])
    jac = (fx / z, 0.0, -fx * cx / z, 0.0, fy / z, -fy * cy / z)
    for i in range(2):
        for j in range(3):
            g[_G_T + 3 * i + j] = jac[3 * i] * r[0, j] + jac[3 * i + 1] * r[1, j] + jac[3 * i + 2] * r[2, j]
    qn, qnorm, q_ok, rq = _rotation(np.float64(quat[0]), np.float64(quat[1]), np.float64(quat[2]), np.float64(quat[3]))
    s0, s1, s2 = np.float64(scale[0]), np.float64(scale[1]), np.float64(scale[2])
    for i in range(3):
        g[_G_RQ + 3 * i] = rq[3 * i]
        g[_G_RQ + 3 * i + 1] = rq[3 * i + 1]
        g[_G_RQ + 3 * i + 2] = rq[3 * i + 2]
        g[_G_M + 3 * i] = rq[3 * i] * s0
        g[_G_M + 3 * i + 1] = rq[3 * i + 1] * s1
        g[_G_M + 3 * i + 2] = rq[3 * i + 2] * s2
    for i in range(3):
        for j in range(3):
            g[_G_SIGMA + 3 * i + j] = (
                g[_G_M + 3 * i] * g[_G_M + 3 * j]
                + g[_G_M + 3 * i + 1] * g[_G_M + 3 * j + 1]
                + g[_G_M + 3 * i + 2] * g[_G_M + 3 * j + 2]
            )
    for i in range(2):
        for j in range(3):
            g[_G_TS + 3 * i + j] = (
                g[_G_T + 3 * i] * g[_G_SIGMA + j]
                + g[_G_T + 3 * i + 1] * g[_G_SIGMA + 3 + j]
                + g[_G_T + 3 * i + 2] * g[_G_SIGMA + 6 + j]
            )
    tm, ts = _G_T, _G_TS
    g[_G_COV] = g[ts] * g[tm] + g[ts + 1] * g[tm + 1] + g[ts + 2] * g[tm + 2] + EPS2D
    g[_G_COV + 1] = g[ts] * g[tm + 3] + g[ts + 1] * g[tm + 4] + g[ts + 2] * g[tm + 5]
    g[_G_COV + 2] = g[ts + 3] * g[tm + 3] + g[ts + 4] * g[tm + 4] + g[ts + 5] * g[tm + 5] + EPS2D
    g[_G_JAC] = jac[2]
    g[_G_JAC + 1] = jac[5]
    return x, y, z, cx != rx, cy != ry, q_ok, qn, qnorm


# slots of the per-pair scratch row filled by _geometry
_G_T, _G_RQ, _G_M, _G_SIGMA, _G_TS, _G_COV, _G_JAC, _G_SIZE = 0, 6, 15, 24, 33, 39, 42, 44


@njit(**JIT)
def _sh_basis(dx, dy, dz, degree):
    """The 16 real SH basis values at direction d (zeros above ``degree``)."""
    b1 = b2 = b3 = b4 = b5 = b6 = b7 = b8 = b9 = b10 = b11 = b12 = b13 = b14 = b15 = 0.0
    if degree >= 1:
        b1, b2, b3 = -SH_C1 * dy, SH_C1 * dz, -SH_C1 * dx
    if degree >= 2:
        xx, yy, zz = dx * dx, dy * dy, dz * dz
        b4 = SH_C2[0] * dx * dy
        b5 = SH_C2[1] * dy * dz
        b6 = SH_C2[2] * (2 * zz - xx - yy)
        b7 = SH_C2[3] * dx * dz
        b8 = SH_C2[4] * (xx - yy)
        if degree >= 3:
            b9 = SH_C3[0] * dy * (3 * xx - yy)
            b10 = SH_C3[1] * dx * dy * dz
            b11 = SH_C3[2] * dy * (4 * zz - xx - yy)
            b12 = SH_C3[3] * dz * (2 * zz - 3 * xx - 3 * yy)
            b13 = SH_C3[4] * dx * (4 * zz - xx - yy)
            b14 = SH_C3[5] * dz * (xx - yy)
            b15 = SH_C3[6] * dx * (xx - 3 * yy)
    return (SH_C0, b1, b2, b3, b4, b5, b6, b7, b8, b9, b10, b11, b12, b13, b14, b15)


@njit(**JIT)
def _sh_basis_grad(x, y, z, degree, gb):
    """Gradient of sum_k gb[k] basis_k(d) with respect to the direction d = (x, y, z)."""
    g0 = g1 = g2 = 0.0
    if degree < 1:
        return g0, g1, g2
    g1 += -SH_C1 * gb[1]
    g2 += SH_C1 * gb[2]
    g0 += -SH_C1 * gb[3]
    if degree < 2:
        return g0, g1, g2
    xx, yy, zz = x * x, y * y, z * z
    g0 += SH_C2[0] * y * gb[4]
    g1 += SH_C2[0] * x * gb[4]
    g1 += SH_C2[1] * z * gb[5]
    g2 += SH_C2[1] * y * gb[5]
    g0 += -2 * SH_C2[2] * x * gb[6]
    g1 += -2 * SH_C2[2] * y * gb[6]
    g2 += 4 * SH_C2[2] * z * gb[6]
    g0 += SH_C2[3] * z * gb[7]
    g2 += SH_C2[3] * x * gb[7]
    g0 += 2 * SH_C2[4] * x * gb[8]
    g1 += -2 * SH_C2[4] * y * gb[8]
    if degree < 3:
        return g0, g1, g2
    g0 += SH_C3[0] * 6 * x * y * gb[9]
    g1 += SH_C3[0] * (3 * xx - 3 * yy) * gb[9]
    g0 += SH_C3[1] * y * z * gb[10]
    g1 += SH_C3[1] * x * z * gb[10]
    g2 += SH_C3[1] * x * y * gb[10]
    g0 += SH_C3[2] * (-2 * x * y) * gb[11]
    g1 += SH_C3[2] * (4 * zz - xx - 3 * yy) * gb[11]
    g2 += SH_C3[2] * 8 * y * z * gb[11]
    g0 += SH_C3[3] * (-6 * x * z) * gb[12]
    g1 += SH_C3[3] * (-6 * y * z) * gb[12]
    g2 += SH_C3[3] * (6 * zz - 3 * xx - 3 * yy) * gb[12]
    g0 += SH_C3[4] * (4 * zz - 3 * xx - yy) * gb[13]
    g1 += SH_C3[4] * (-2 * x * y) * gb[13]
    g2 += SH_C3[4] * 8 * x * z * gb[13]
    g0 += SH_C3[5] * 2 * x * z * gb[14]
    g1 += SH_C3[5] * (-2 * y * z) * gb[14]
    g2 += SH_C3[5] * (xx - yy) * gb[14]
    g0 += SH_C3[6] * (3 * xx - 3 * yy) * gb[15]
    g1 += SH_C3[6] * (-6 * x * y) * gb[15]
    return g0, g1, g2


@njit(**JIT)
def _view_dir(centre, mean):
    """(unit direction from the camera centre to ``mean``, distance)."""
    dx, dy, dz = np.float64(mean[0]) - centre[0], np.float64(mean[1]) - centre[1], np.float64(mean[2]) - centre[2]
    length = math.sqrt(dx * dx + dy * dy + dz * dz)
    inv = 1.0 / max(length, 1e-12)
    return dx * inv, dy * inv, dz * inv, length


@njit(parallel=True, **JIT)
def project_forward(means, quats, scales, opacities, sh, viewmats, ks, width, height, near, far, sh_degree, dense):
    """Dense (B, N) projection: fills ``dense`` = (means2d, conics, rgb, depth, radii, rects, valid) in place."""
    o_m, o_c, o_rgb, o_d, o_r, o_rect, o_v = dense
    n_cams, n = viewmats.shape[0], means.shape[0]
    tiles_x = (width + TILE - 1) // TILE
    tiles_y = (height + TILE - 1) // TILE
    n_basis = (sh_degree + 1) * (sh_degree + 1)
    for bi in range(n_cams):
        r, t, fx, fy, cx, cy, centre, lims = _camera(viewmats[bi], ks[bi], width, height)
        for gi in prange(n):
            o_v[bi, gi] = False
            o = np.float64(opacities[gi])
            if not (o >= ALPHA_MIN):
                continue
            g = np.empty(_G_SIZE)
            x, y, z, _, _, _, _, _ = _geometry(r, t, fx, fy, lims, means[gi], quats[gi], scales[gi], g)
            a, b, c = g[_G_COV], g[_G_COV + 1], g[_G_COV + 2]
            det = a * c - b * b
            if not (z > near and z < far) or not (det > 0) or not math.isfinite(det):
                continue
            u = fx * x / z + cx
            v = fy * y / z + cy
            r2 = 2.0 * math.log(255.0 * o)
            rad_x = math.sqrt(r2 * a) * (1.0 + 1e-4) + 1e-3
            rad_y = math.sqrt(r2 * c) * (1.0 + 1e-4) + 1e-3
            if not (math.isfinite(u) and math.isfinite(v) and math.isfinite(rad_x) and math.isfinite(rad_y)):
                continue
            # np.ceil/np.floor stay floats (math's return integers, which overflow for huge footprints)
            lo_x = max(0.0, np.ceil(u - rad_x - 0.5))
            hi_x = min(np.float64(width - 1), np.floor(u + rad_x - 0.5))
            lo_y = max(0.0, np.ceil(v - rad_y - 0.5))
            hi_y = min(np.float64(height - 1), np.floor(v + rad_y - 0.5))
            if lo_x > hi_x or lo_y > hi_y:
                continue
            o_rect[bi, gi, 0] = min(int(lo_x) // TILE, tiles_x - 1)
            o_rect[bi, gi, 1] = min(int(lo_y) // TILE, tiles_y - 1)
            o_rect[bi, gi, 2] = int(hi_x) // TILE
            o_rect[bi, gi, 3] = int(hi_y) // TILE
            o_v[bi, gi] = True
            o_m[bi, gi, 0] = u
            o_m[bi, gi, 1] = v
            inv_det = 1.0 / det
            o_c[bi, gi, 0] = c * inv_det
            o_c[bi, gi, 1] = -b * inv_det
            o_c[bi, gi, 2] = a * inv_det
            o_d[bi, gi] = z
            o_r[bi, gi, 0] = rad_x
            o_r[bi, gi, 1] = rad_y
            if sh_degree >= 0:
                dx, dy, dz, _ = _view_dir(centre, means[gi])
                basis = _sh_basis(dx, dy, dz, sh_degree)
                for ch in range(3):
                    acc = 0.5
                    for kk in range(n_basis):
                        acc += basis[kk] * np.float64(sh[gi, kk, ch])
                    o_rgb[bi, gi, ch] = max(acc, 0.0)


@njit(**JIT)
def _sh_backward(centre, mean, shc, sh_degree, g_rgb, gsh):
    """An entry's SH colour backward: adds to the Gaussian's SH gradient ``gsh``; returns the view direction's
    share of the mean's gradient (zero for degree 0)."""
    dx, dy, dz, length = _view_dir(centre, mean)
    basis = _sh_basis(dx, dy, dz, sh_degree)
    n_basis = (sh_degree + 1) * (sh_degree + 1)
    gb = np.zeros(16)
    for ch in range(3):
        acc = 0.5
        for kk in range(n_basis):
            acc += basis[kk] * np.float64(shc[kk, ch])
        if acc < 0.0:  # clamped channel
            continue
        gc = np.float64(g_rgb[ch])
        for kk in range(n_basis):
            gsh[kk, ch] += basis[kk] * gc
            gb[kk] += np.float64(shc[kk, ch]) * gc
    if sh_degree > 0 and length > 1e-12:
        g0, g1, g2 = _sh_basis_grad(dx, dy, dz, sh_degree, gb)
        dot = g0 * dx + g1 * dy + g2 * dz
        return (g0 - dx * dot) / length, (g1 - dy * dot) / length, (g2 - dz * dot) / length
    return 0.0, 0.0, 0.0


@njit(parallel=True, **JIT)
def project_backward(
    means, quats, scales, sh, viewmats, ks, width, height, sh_degree, cam_ids, gauss_ids, grads, geometry, outs
):
    """Adds the entries' gradients into ``outs`` = (means, quats, scales, sh); ``grads`` = (means2d, conics,
    rgb, depth) of the entries (sorted by camera; a Gaussian appears at most once per camera: no races)."""
    g_m2, g_con, g_rgb, g_depth = grads
    gm, gq, gs, gsh = outs
    m, n_cams = cam_ids.shape[0], viewmats.shape[0]
    start = 0
    for bi in range(n_cams):
        stop = start
        while stop < m and cam_ids[stop] == bi:
            stop += 1
        r, t, fx, fy, _, _, centre, lims = _camera(viewmats[bi], ks[bi], width, height)
        for e in prange(start, stop):
            n = gauss_ids[e]
            if not geometry:
                if sh_degree >= 0:
                    _sh_backward(centre, means[n], sh[n], sh_degree, g_rgb[e], gsh[n])
                continue
            g = np.empty(_G_SIZE)
            x, y, z, clamp_x, clamp_y, q_ok, qn, qnorm = _geometry(r, t, fx, fy, lims, means[n], quats[n], scales[n], g)
            dp0, dp1, dp2 = 0.0, 0.0, np.float64(g_depth[e])
            gu, gv = np.float64(g_m2[e, 0]), np.float64(g_m2[e, 1])
            dp0 += gu * fx / z
            dp1 += gv * fy / z
            dp2 += -gu * fx * x / (z * z) - gv * fy * y / (z * z)
            a, b, c = g[_G_COV], g[_G_COV + 1], g[_G_COV + 2]
            inv_det = 1.0 / (a * c - b * b)
            q00, q01, q11 = c * inv_det, -b * inv_det, a * inv_det
            G00, G01, G11 = np.float64(g_con[e, 0]), 0.5 * np.float64(g_con[e, 1]), np.float64(g_con[e, 2])
            qg00, qg01 = q00 * G00 + q01 * G01, q00 * G01 + q01 * G11
            qg10, qg11 = q01 * G00 + q11 * G01, q01 * G01 + q11 * G11
            dc00 = -(qg00 * q00 + qg01 * q01)
            dc01 = -(qg00 * q01 + qg01 * q11)
            dc11 = -(qg10 * q01 + qg11 * q11)
            gcov = (dc00, dc01, dc01, dc11)
            tm, sg = _G_T, _G_SIGMA
            gt = np.empty(6)
            for i in range(2):
                for j in range(3):
                    gt[3 * i + j] = gcov[2 * i] * g[tm + j] + gcov[2 * i + 1] * g[tm + 3 + j]
            dsigma = np.empty(9)
            for i in range(3):
                for j in range(3):
                    dsigma[3 * i + j] = g[tm + i] * gt[j] + g[tm + 3 + i] * gt[3 + j]
            dt = np.empty(6)
            for i in range(2):
                for j in range(3):
                    dt[3 * i + j] = 2.0 * (
                        gt[3 * i] * g[sg + j] + gt[3 * i + 1] * g[sg + 3 + j] + gt[3 * i + 2] * g[sg + 6 + j]
                    )
            dj = np.empty(6)
            for i in range(2):
                for j in range(3):
                    dj[3 * i + j] = dt[3 * i] * r[j, 0] + dt[3 * i + 1] * r[j, 1] + dt[3 * i + 2] * r[j, 2]
            z2 = z * z
            z3 = z2 * z
            dp2 += -dj[0] * fx / z2 - dj[4] * fy / z2
            if clamp_x:
                dp2 += dj[2] * fx * (-g[_G_JAC] / fx * z) / z2
            else:
                dp0 += -dj[2] * fx / z2
                dp2 += dj[2] * 2.0 * fx * x / z3
            if clamp_y:
                dp2 += dj[5] * fy * (-g[_G_JAC + 1] / fy * z) / z2
            else:
                dp1 += -dj[5] * fy / z2
                dp2 += dj[5] * 2.0 * fy * y / z3
            dmean = np.empty(3)
            for j in range(3):
                dmean[j] = r[0, j] * dp0 + r[1, j] * dp1 + r[2, j] * dp2
            rq = _G_RQ
            dr = np.empty(9)
            for j in range(3):
                sj = np.float64(scales[n, j])
                acc_s = 0.0
                for i in range(3):
                    acc = 0.0
                    for kk in range(3):
                        acc += (dsigma[3 * i + kk] + dsigma[3 * kk + i]) * g[rq + 3 * kk + j] * sj
                    dr[3 * i + j] = acc * sj
                    acc_s += acc * g[rq + 3 * i + j]
                gs[n, j] += acc_s
            if q_ok:
                w, qx, qy, qz = qn
                dqn = (
                    2 * (-qz * dr[1] + qy * dr[2] + qz * dr[3] - qx * dr[5] - qy * dr[6] + qx * dr[7]),
                    2
                    * (
                        qy * dr[1]
                        + qz * dr[2]
                        + qy * dr[3]
                        - 2 * qx * dr[4]
                        - w * dr[5]
                        + qz * dr[6]
                        + w * dr[7]
                        - 2 * qx * dr[8]
                    ),
                    2
                    * (
                        -2 * qy * dr[0]
                        + qx * dr[1]
                        + w * dr[2]
                        + qx * dr[3]
                        + qz * dr[5]
                        - w * dr[6]
                        + qz * dr[7]
                        - 2 * qy * dr[8]
                    ),
                    2
                    * (
                        -2 * qz * dr[0]
                        - w * dr[1]
                        + qx * dr[2]
                        + w * dr[3]
                        - 2 * qz * dr[4]
                        + qy * dr[5]
                        + qx * dr[6]
                        + qy * dr[7]
                    ),
                )
                dot = dqn[0] * w + dqn[1] * qx + dqn[2] * qy + dqn[3] * qz
                for i in range(4):
                    gq[n, i] += (dqn[i] - qn[i] * dot) / qnorm
            if sh_degree >= 0:
                d0, d1, d2 = _sh_backward(centre, means[n], sh[n], sh_degree, g_rgb[e], gsh[n])
                dmean[0] += d0
                dmean[1] += d1
                dmean[2] += d2
            for i in range(3):
                gm[n, i] += dmean[i]
        start = stop
