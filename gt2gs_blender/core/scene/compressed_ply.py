"""PlayCanvas compressed PLY (``.compressed.ply``): read and written with numpy only.

The layout (a binary PLY; elements in this order, all little endian as written here):

- ``chunk``, ceil(N / 256) rows of floats: the ranges of chunk k, which holds splats 256k .. 256k + 255
  (the last chunk may hold fewer): ``min_x min_y min_z max_x max_y max_z``, then the log scales'
  ``min_scale_x .. max_scale_z`` (clamped to [-20, 20]), then optionally (older files lack them)
  ``min_r min_g min_b max_r max_g max_b`` of the base colour 0.5 + SH_C0 * f_dc (not clipped to 0..1).
- ``vertex``, N rows of four uint32 words; a field of b bits holds q, the fraction t = q / (2^b - 1) of
  its chunk's range (value = min + t (max - min)):
  ``packed_position`` x, y, z in 11, 10, 11 bits (bits 31-21, 20-11, 10-0); ``packed_scale`` the log
  scales, packed the same way; ``packed_rotation`` the unit quaternion as "smallest three": bits 31-30
  the index (w, x, y, z order, i.e. rot_0 .. rot_3) of its largest component, made positive, then the
  other three in index order, 10 bits each (29-20, 19-10, 9-0), t mapped to [-1/sqrt 2, 1/sqrt 2],
  the largest rebuilt as sqrt(1 - their squares); ``packed_color`` 8 bits each of r, g, b (bits 31-24,
  23-16, 15-8; fractions of the colour range, or the colour itself without ranges) and of the
  activated opacity sigmoid(logit) in 0..1 (bits 7-0).
- ``sh`` (only for SH degree 1-3), N rows of uchar ``f_rest_0 .. f_rest_<3K-1>`` in INRIA's
  channel-major order: byte b reads as 8 ((b + 0.5) / 256 - 0.5), with 0 and 255 read as -4 and 4.

Precision kept (the largest error, from rounding to the nearest step): positions and log scales half
a step, range / 2047 for x and z, range / 1023 for y, so it depends on how compact each chunk of 256
is; quaternion components sqrt 2 / 2046 = 6.9e-4 for the three stored ones, up to 3 times that for
the rebuilt largest; colours half of range / 255; opacity 1 / 510 (activated); SH coefficients 1 / 64
inside [-4, 4], beyond which they are clipped. Opacities of 0 and 1 read back as logits of +-13.8
(``codec.logit``), not as infinities.

Order: splat-transform's writer sorts splats in Morton order (tighter chunk ranges); the format does
not require any order, and ``write_compressed_ply`` keeps the scene's. The reader returns the file's.
Extras (normals, custom properties) have no place in the format and are dropped with a note.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..atomic import atomic_write
from ..errors import PlyFormatError, SplatFormatError
from .arrays import SplatArrays
from .codec import (
    PathLike,
    as_arrays,
    canonical_quats,
    colour_from_dc,
    dc_from_colour,
    dropped_notes,
    from_smallest_three,
    logit,
    make_arrays,
    read_bytes,
    require_finite,
    sigmoid,
    smallest_three,
)
from .inria import REST_PREFIX, rest_per_channel, tensor_view
from .ply_header import FORMATS, HEADER_LIMIT, SCALAR_TYPES, PlyElement, PlyHeader, _parse_header

if TYPE_CHECKING:
    from .gaussians import GaussianScene

CHUNK_SIZE = 256
"""Splats per chunk (one row of ranges)."""
POSITION_RANGES = ("min_x", "min_y", "min_z", "max_x", "max_y", "max_z")
SCALE_RANGES = tuple(f"{end}_scale_{axis}" for end in ("min", "max") for axis in "xyz")
COLOUR_RANGES = ("min_r", "min_g", "min_b", "max_r", "max_g", "max_b")
PACKED = ("packed_position", "packed_rotation", "packed_scale", "packed_color")
BITS_11_10_11 = (11, 10, 11)
SCALE_LIMIT = 20.0
"""Log-scale ranges are clamped to [-20, 20], as PlayCanvas's writer does."""
SH_LIMIT = 4.0
"""SH coefficients are stored in [-4, 4]."""
ROTATION_LIMIT = 1.0 / np.sqrt(2.0)
"""The three smaller components of a unit quaternion lie in [-1/sqrt 2, 1/sqrt 2]."""
MIN_RANGE = 1e-5
"""A chunk range narrower than this stores every value as its minimum (as PlayCanvas's writer does)."""


def is_compressed_ply(header: PlyHeader) -> bool:
    """Whether a parsed PLY header is a compressed PLY: a ``chunk`` element and packed_* vertex properties."""
    has_chunk = any(element.name == "chunk" for element in header.elements)
    return has_chunk and any(name.startswith("packed_") for name, _ in header.properties)


def read_compressed_ply(path: PathLike, *, drop_invalid: bool = False) -> SplatArrays:
    """Load a compressed PLY as numpy arrays, in the file's splat order (see the module docstring)."""
    data = read_bytes(path)
    try:
        header = _parse_header(path, data[:HEADER_LIMIT])
    except PlyFormatError as exc:
        raise SplatFormatError(path, exc.problem) from None
    chunk, vertex = _check_layout(path, header)
    records = _element_records(path, data, header)
    ranges, packed = records["chunk"], records["vertex"]
    bad_chunks = _non_finite_chunks(ranges)
    if len(bad_chunks) and not drop_invalid:
        shown = ", ".join(map(str, bad_chunks[:5])) + (", ..." if len(bad_chunks) > 5 else "")
        raise SplatFormatError(
            path,
            f"{len(bad_chunks)} of {chunk.count} chunks have NaN or Inf ranges (chunk {shown}); "
            "use --drop-invalid (drop_invalid=True) to load the file without their splats",
        )
    rows = np.arange(vertex.count) // CHUNK_SIZE
    with np.errstate(invalid="ignore", over="ignore"):
        colour = _unpack_colour(packed["packed_color"], ranges, rows)
        return make_arrays(
            path,
            means=_unpack_ranged(packed["packed_position"], ranges, rows, POSITION_RANGES),
            quats=_unpack_rotation(packed["packed_rotation"]),
            log_scales=_unpack_ranged(packed["packed_scale"], ranges, rows, SCALE_RANGES),
            opacity_logits=logit(_unpack_unorm(packed["packed_color"], 0, 8)),
            sh_dc=dc_from_colour(colour),
            sh_rest=_unpack_sh(records["sh"], vertex.count),
            drop_invalid=drop_invalid,
        )


def _check_layout(path: PathLike, header: PlyHeader) -> tuple[PlyElement, PlyElement]:
    """The chunk and vertex elements, checked (with the optional sh element) against the compressed PLY layout."""
    if header.format == "ascii":
        raise SplatFormatError(path, "a compressed PLY must be binary, this one is ascii")
    elements = {element.name: element for element in header.elements}
    if "chunk" not in elements:
        raise SplatFormatError(path, "no 'chunk' element: not a compressed PLY")
    chunk, vertex, sh = elements["chunk"], header.vertex, elements.get("sh")
    lists = [f"{e.name}.{p.name}" for e in header.elements for p in e.properties if p.list_count_type]
    if lists:
        raise SplatFormatError(path, f"list properties ({', '.join(lists)}) have no place in a compressed PLY")
    expected_chunks = -(-vertex.count // CHUNK_SIZE)
    if chunk.count != expected_chunks:
        raise SplatFormatError(
            path,
            f"{chunk.count} chunks for {vertex.count} splats; expected ceil({vertex.count} / {CHUNK_SIZE}) = "
            f"{expected_chunks} (corrupt header?)",
        )
    _require(path, vertex, PACKED, ("u4", "i4"), "32-bit integer")
    _require(path, chunk, POSITION_RANGES + SCALE_RANGES, ("f4", "f8"), "float")
    chunk_names = {p.name for p in chunk.properties}
    if chunk_names & set(COLOUR_RANGES):
        _require(path, chunk, COLOUR_RANGES, ("f4", "f8"), "float")
    if sh is not None:
        _check_sh(path, sh, vertex.count)
    return chunk, vertex


def _require(path: PathLike, element: PlyElement, names: tuple[str, ...], codes: tuple[str, ...], kind: str) -> None:
    """Every property in ``names`` exists in ``element`` and has a type in ``codes``."""
    types = {p.name: p.type for p in element.properties}
    missing = [name for name in names if name not in types]
    if missing:
        raise SplatFormatError(path, f"the {element.name!r} element lacks {', '.join(missing)} (not a compressed PLY?)")
    wrong = [f"{name} ({types[name]})" for name in names if SCALAR_TYPES[types[name]] not in codes]
    if wrong:
        raise SplatFormatError(path, f"{element.name!r} properties must be {kind}: {', '.join(wrong)}")


def _check_sh(path: PathLike, sh: PlyElement, n: int) -> None:
    """The ``sh`` element has one uchar row per splat, f_rest_* of SH degree 1-3."""
    if sh.count != n:
        raise SplatFormatError(path, f"the 'sh' element has {sh.count} rows for {n} splats")
    names = [p.name for p in sh.properties]
    if rest_per_channel(names) is None:
        raise SplatFormatError(
            path, f"the 'sh' element's {len(names)} properties are not f_rest_0 .. f_rest_<n-1> with n = 9, 24 or 45"
        )
    _require(path, sh, tuple(names), ("u1",), "uchar")


def _element_records(path: PathLike, data: bytes, header: PlyHeader) -> dict[str, np.ndarray]:
    """Every element's rows as a structured array (file byte order), by element name."""
    byte_order = FORMATS[header.format]
    records: dict[str, np.ndarray] = {}
    offset = header.header_size
    for element in header.elements:
        dtype = np.dtype([(p.name, byte_order + SCALAR_TYPES[p.type]) for p in element.properties])
        size = element.count * dtype.itemsize
        if offset + size > len(data):
            raise SplatFormatError(
                path,
                f"truncated: the {element.name!r} element needs {size} bytes but only "
                f"{max(len(data) - offset, 0)} follow (truncated file or wrong counts)",
            )
        records[element.name] = np.frombuffer(data, dtype, element.count, offset)
        offset += size
    records.setdefault("sh", None)
    return records


def _non_finite_chunks(ranges: np.ndarray) -> np.ndarray:
    """Indices of chunks with a NaN or Inf range."""
    finite = np.ones(len(ranges), bool)
    for name in POSITION_RANGES + SCALE_RANGES + COLOUR_RANGES:
        if name in ranges.dtype.names:
            finite &= np.isfinite(ranges[name])
    return np.flatnonzero(~finite)


def _unpack_unorm(words: np.ndarray, shift: int, bits: int) -> np.ndarray:
    """The ``bits``-bit field at ``shift`` of uint32 ``words`` as a fraction in [0, 1] (float64)."""
    mask = (1 << bits) - 1
    return ((words.astype(np.uint32) >> np.uint32(shift)) & np.uint32(mask)) / mask


def _unpack_111011(words: np.ndarray) -> np.ndarray:
    """(N, 3) fractions of an 11-10-11 packed word (x in the high bits)."""
    return np.stack([_unpack_unorm(words, 21, 11), _unpack_unorm(words, 11, 10), _unpack_unorm(words, 0, 11)], 1)


def _range_columns(ranges: np.ndarray, rows: np.ndarray, names: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray]:
    """The (N, 3) minima and maxima that ``names`` (three min then three max) give each splat's chunk."""
    table = np.stack([ranges[name].astype(np.float64) for name in names], 1)[rows]
    return table[:, :3], table[:, 3:]


def _lerp(lo: np.ndarray, hi: np.ndarray, t: np.ndarray) -> np.ndarray:
    """lo + t (hi - lo), written as PlayCanvas's reader evaluates it."""
    return lo * (1.0 - t) + hi * t


def _unpack_ranged(words: np.ndarray, ranges: np.ndarray, rows: np.ndarray, names: tuple[str, ...]) -> np.ndarray:
    """(N, 3) values of an 11-10-11 word against the chunk ranges ``names``."""
    lo, hi = _range_columns(ranges, rows, names)
    return _lerp(lo, hi, _unpack_111011(words))


def _unpack_colour(words: np.ndarray, ranges: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """(N, 3) base colours from packed_color's r, g, b bytes (against the colour ranges when present)."""
    t = np.stack([_unpack_unorm(words, shift, 8) for shift in (24, 16, 8)], 1)
    if COLOUR_RANGES[0] not in ranges.dtype.names:
        return t
    lo, hi = _range_columns(ranges, rows, COLOUR_RANGES)
    return _lerp(lo, hi, t)


def _unpack_rotation(words: np.ndarray) -> np.ndarray:
    """(N, 4) quaternions (w, x, y, z) from smallest-three words."""
    words = words.astype(np.uint32)
    small = np.stack([(_unpack_unorm(words, shift, 10) - 0.5) / ROTATION_LIMIT for shift in (20, 10, 0)], 1)
    return from_smallest_three((words >> np.uint32(30)).astype(np.intp), small)


def _unpack_sh(records: np.ndarray | None, n: int) -> np.ndarray:
    """(N, K, 3) SH rest coefficients from the sh element's bytes (K = 0 without one)."""
    k = 0 if records is None else rest_per_channel(records.dtype.names or ())
    if not k:
        return np.zeros((n, 0, 3))
    names = [f"{REST_PREFIX}{i}" for i in range(3 * k)]
    codes = np.stack([records[name] for name in names], 1).astype(np.float64)
    fraction = np.where(codes == 0, 0.0, np.where(codes == 255, 1.0, (codes + 0.5) / 256.0))
    return tensor_view("sh_rest", 2.0 * SH_LIMIT * (fraction - 0.5))


def write_compressed_ply(path: PathLike, scene: GaussianScene | SplatArrays) -> list[str]:
    """Write a scene as a compressed PLY atomically, in the scene's splat order; return one-line notes
    on what the format could not keep. ``SplatFormatError`` naming ``path`` for a scene with NaN/Inf values."""
    arrays = as_arrays(scene)
    n = len(arrays)
    require_finite(path, arrays, "compressed PLY")
    means = arrays.means.astype(np.float32)
    log_scales = arrays.log_scales.astype(np.float32)
    colour = colour_from_dc(arrays.sh_dc.astype(np.float32))
    starts = np.arange(0, n, CHUNK_SIZE)
    position_lo, position_hi = _chunk_ranges(means, starts)
    scale_lo, scale_hi = (np.clip(r, -SCALE_LIMIT, SCALE_LIMIT) for r in _chunk_ranges(log_scales, starts))
    colour_lo, colour_hi = _chunk_ranges(colour, starts)
    rows = np.arange(n) // CHUNK_SIZE
    vertex = np.empty((n, 4), "<u4")
    vertex[:, 0] = _pack_111011(_fractions(means, position_lo[rows], position_hi[rows]))
    vertex[:, 1] = _pack_rotation(arrays.quats)
    vertex[:, 2] = _pack_111011(_fractions(log_scales, scale_lo[rows], scale_hi[rows]))
    colour_t = _fractions(colour, colour_lo[rows], colour_hi[rows])
    opacity = sigmoid(arrays.opacity_logits)
    vertex[:, 3] = _pack_8888(colour_t[:, 0], colour_t[:, 1], colour_t[:, 2], opacity)
    ranges = np.concatenate([position_lo, position_hi, scale_lo, scale_hi, colour_lo, colour_hi], 1).astype("<f4")
    k = int(arrays.sh_rest.shape[1])
    sh = _pack_sh(arrays.sh_rest)
    atomic_write(Path(path), (_header(n, len(starts), k), ranges, vertex, sh))
    return _notes(arrays)


def _chunk_ranges(values: np.ndarray, starts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-chunk (C, 3) minima and maxima of (N, 3) ``values``, rounded to the float32 the file stores."""
    if len(values) == 0:
        empty = np.zeros((0, 3), np.float32)
        return empty, empty
    lo = np.minimum.reduceat(values, starts, axis=0).astype(np.float32)
    hi = np.maximum.reduceat(values, starts, axis=0).astype(np.float32)
    return lo, hi


def _fractions(values: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Each value's place t in [0, 1] within its range; 0 for a range narrower than ``MIN_RANGE``."""
    lo, hi = lo.astype(np.float64), hi.astype(np.float64)
    span = hi - lo
    wide = span >= MIN_RANGE
    t = (np.asarray(values, np.float64) - lo) / np.where(wide, span, 1.0)
    return np.where(wide, np.clip(t, 0.0, 1.0), 0.0)


def _pack_unorm(t: np.ndarray, bits: int) -> np.ndarray:
    """Fractions in [0, 1] rounded to the nearest of 2^bits steps, as uint32."""
    mask = (1 << bits) - 1
    return np.clip(np.floor(np.asarray(t, np.float64) * mask + 0.5), 0, mask).astype(np.uint32)


def _pack_111011(t: np.ndarray) -> np.ndarray:
    """(N, 3) fractions packed as 11-10-11 bit words (x in the high bits)."""
    x, y, z = (_pack_unorm(t[:, i], bits) for i, bits in enumerate(BITS_11_10_11))
    return (x << np.uint32(21)) | (y << np.uint32(11)) | z


def _pack_8888(r: np.ndarray, g: np.ndarray, b: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Four fractions packed as 8-bit fields of a word (r in the high bits)."""
    fields = [_pack_unorm(value, 8) for value in (r, g, b, a)]
    return (fields[0] << np.uint32(24)) | (fields[1] << np.uint32(16)) | (fields[2] << np.uint32(8)) | fields[3]


def _pack_rotation(quats: np.ndarray) -> np.ndarray:
    """(N, 4) quaternions (w, x, y, z) as smallest-three words: the largest's index and three 10-bit components."""
    largest, others = smallest_three(canonical_quats(quats))
    fields = _pack_unorm(others * ROTATION_LIMIT + 0.5, 10)
    word = largest.astype(np.uint32) << np.uint32(30)
    return word | (fields[:, 0] << np.uint32(20)) | (fields[:, 1] << np.uint32(10)) | fields[:, 2]


def _pack_sh(sh_rest: np.ndarray) -> np.ndarray:
    """(N, 3K) bytes of the SH rest coefficients in channel-major order (the reader's bins, clipped to [-4, 4])."""
    n, k = sh_rest.shape[:2]
    storage = np.empty((n, 3 * k), np.float64)
    np.copyto(tensor_view("sh_rest", storage), sh_rest)
    codes = np.floor((storage / (2.0 * SH_LIMIT) + 0.5) * 256.0)
    return np.clip(codes, 0, 255).astype(np.uint8)


def _header(n: int, n_chunks: int, k: int) -> bytes:
    """The ASCII header of a compressed PLY with ``n`` splats and K SH rest coefficients per channel."""
    lines = [
        "ply",
        "format binary_little_endian 1.0",
        "comment Generated by GT2 Texture Transfer",
        f"element chunk {n_chunks}",
        *(f"property float {name}" for name in POSITION_RANGES + SCALE_RANGES + COLOUR_RANGES),
        f"element vertex {n}",
        *(f"property uint {name}" for name in PACKED),
    ]
    if k:
        lines += [f"element sh {n}", *(f"property uchar {REST_PREFIX}{i}" for i in range(3 * k))]
    return ("\n".join([*lines, "end_header"]) + "\n").encode("ascii")


def _notes(arrays: SplatArrays) -> list[str]:
    """One line for each kind of information the compressed PLY did not keep."""
    notes = dropped_notes(arrays, "compressed PLY", 3)
    n_scales = int(np.count_nonzero(np.abs(arrays.log_scales) > SCALE_LIMIT))
    if n_scales:
        notes.append(f"clamped {n_scales} log scales outside [-{SCALE_LIMIT:g}, {SCALE_LIMIT:g}]")
    n_sh = int(np.count_nonzero(np.abs(arrays.sh_rest) > SH_LIMIT))
    if n_sh:
        notes.append(f"clipped {n_sh} SH coefficients outside [-{SH_LIMIT:g}, {SH_LIMIT:g}]")
    return notes
