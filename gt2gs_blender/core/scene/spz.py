"""Read and write Niantic's SPZ splat files (``.spz``): versions 2 and 3, and version 4 read only. numpy only
(version 4 also needs ``zstandard``, which Blender bundles).

Layout. A version 2 or 3 file is one gzip stream. Inside, a 16-byte little-endian header: magic
``NGSP`` (u32 0x5053474e), version (u32), point count N (u32), SH degree (u8, 0-3 here), fractional
bits F (u8), flags (u8: 0x1 trained with antialiasing, 0x2 extension records follow) and a reserved
byte. Then one block per attribute, each for all N points in turn:

- positions, 9 bytes a point: x, y, z as signed 24-bit little-endian fixed point, value = integer /
  2^F: steps of 2^-F over +-2^(23-F) units. The writer uses Niantic's F = 12 (1/4096 over +-2048),
  fewer bits only when a position needs the range;
- opacities, 1 byte: sigmoid(logit) * 255 (steps of 1/255 in opacity);
- colours, 3 bytes: the DC SH coefficient as (0.5 + 0.15 dc) * 255. The factor is 0.15, not SH_C0:
  DC steps of 1/38.25, colours 0.5 + SH_C0 dc from -0.44 to 1.44 (steps of 0.0074);
- scales, 3 bytes: (log scale + 10) * 16 (log scales -10..5.94 in steps of 1/16);
- rotations, the unit quaternion in x, y, z, w order. Version 2: 3 bytes, x, y, z as (v + 1) * 127.5
  with w >= 0 rebuilt from the unit norm (coarse when w is small). Versions 3 and 4: "smallest three"
  in a little-endian u32: the index of the largest-magnitude component (made positive) in the top
  2 bits, then the other three in index order from the high bits down, 10 bits each: a sign bit over
  a 9-bit magnitude |v| / sqrt(1/2) * 511;
- SH bands 1-3, (degree + 1)^2 - 1 coefficients a point, coefficient-major with the 3 colour channels
  innermost (the engine's ``sh_rest[:, k, c]``), each a byte v * 128 + 128 (v from -1 to 0.99).
  Writers may keep fewer bits: the reference writer (and this one, by default) keeps 5 for band 1 and
  4 for bands 2-3 (steps of 1/16 and 1/8); every byte decodes the same way.

Version 4 has a plain 32-byte header (the same fields, the reserved byte now counting the data streams,
then the u32 offset of a table of contents and 12 reserved bytes), extension records up to that
table, the table (per stream: compressed and decompressed u64 sizes), then the blocks above as
separate zstd streams (no SH stream for degree 0). Version 1 (half-float positions) is refused.

Axes: the format carries no coordinate metadata. PlayCanvas splat-transform reads and writes the values
as they are (PLY space, no axis flips), and so does this module: a PLY converted by splat-transform
reads back with its own axes. (Niantic's own library stores RUB and flips y and z only when a caller
names the source or target coordinate system.)

Not kept: extra per-point properties (normals, ...). The antialiasing flag is read but the engine has
no use for it (a warning says so); files are written without it.
"""

from __future__ import annotations

import gzip
import io
import struct
import warnings
from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from ..atomic import atomic_write
from ..errors import SplatFormatError
from . import codec
from .arrays import SplatArrays
from .codec import (
    PathLike,
    as_arrays,
    canonical_quats,
    dropped_notes,
    from_smallest_three,
    inflate,
    logit,
    make_arrays,
    read_bytes,
    require_finite,
    sigmoid,
    smallest_three,
)
from .inria import sh_degree_from_rest

if TYPE_CHECKING:
    from .gaussians import GaussianScene

MAGIC = 0x5053474E
"""``NGSP`` read as a little-endian u32."""
MAGIC_BYTES = MAGIC.to_bytes(4, "little")
GZIP_VERSIONS = (2, 3)
"""The versions written (one gzip stream); version 4 (zstd) is read only."""
ZSTD_VERSION = 4
HEADER = struct.Struct("<IIIBBBB")
"""Versions 2 and 3: magic, version, count, SH degree, fractional bits, flags, reserved."""
HEADER_V4 = struct.Struct("<IIIBBBBI12x")
"""Version 4: the same, then the number of zstd streams (not a reserved byte) and the table's offset."""
COLOR_SCALE = 0.15
"""DC byte = (0.5 + COLOR_SCALE * f_dc) * 255: a wider colour range than SH_C0 would give."""
LOG_SCALE_OFFSET = 10.0
LOG_SCALE_STEPS = 16.0
SH_BITS = (5, 4)
"""The reference writer's SH precision: bits kept of band 1, of bands 2 and 3."""
FLAG_ANTIALIASED = 0x1
FLAG_EXTENSIONS = 0x2
REFERENCE_FRACTIONAL_BITS = 12
"""Niantic's choice: steps of 1/4096 (0.24 mm in metres) over +-2048 units."""
MAX_FRACTIONAL_BITS = 30
"""Readers compute 1 << F in 32-bit integers."""
_INT24_MAX = 2**23 - 1
_SQRT_HALF = np.sqrt(0.5)
"""The three components a v3 rotation stores, in order, for each index of the dropped largest one."""
_GZIP = b"\x1f\x8b"


class _Header(NamedTuple):
    version: int
    count: int
    sh_degree: int
    fractional_bits: int
    flags: int


def read_spz(path: PathLike, *, drop_invalid: bool = False) -> SplatArrays:
    """Load an SPZ file (version 2, 3 or 4; SH degree 0-3) as numpy arrays."""
    data = read_bytes(path)
    if data[:2] == _GZIP:
        header, blocks = _gzip_blocks(path, data)
    elif data[:4] == MAGIC_BYTES:
        header, blocks = _zstd_blocks(path, data)
    else:
        raise SplatFormatError(path, "not an spz file (neither a gzip stream nor an NGSP header)")
    if header.flags & FLAG_ANTIALIASED:
        warnings.warn(
            f"{path}: trained with antialiasing (mip-splatting); it renders here without that filter", stacklevel=2
        )
    n, k = header.count, (header.sh_degree + 1) ** 2 - 1
    rotations = blocks["rotations"]
    return make_arrays(
        path,
        means=_decode_positions(blocks["positions"], header.fractional_bits),
        quats=_decode_rotations_v2(rotations) if header.version == 2 else _decode_rotations_v3(rotations),
        log_scales=blocks["scales"].reshape(n, 3) / LOG_SCALE_STEPS - LOG_SCALE_OFFSET,
        opacity_logits=logit(blocks["alphas"] / 255.0),
        sh_dc=(blocks["colors"].reshape(n, 3) / 255.0 - 0.5) / COLOR_SCALE,
        sh_rest=(blocks["sh"].reshape(n, k, 3) - 128.0) / 128.0,
        drop_invalid=drop_invalid,
    )


def _gzip_blocks(path: PathLike, data: bytes) -> tuple[_Header, dict[str, np.ndarray]]:
    """Header and attribute blocks of a version 2 or 3 file: one gzip stream, 16-byte header first. The header
    is read first, so a stream never inflates past what its point count needs (no gzip bombs)."""
    head = inflate(path, data, HEADER.size)
    if len(head) < HEADER.size:
        raise SplatFormatError(path, f"truncated: {len(head)} bytes, less than the {HEADER.size}-byte spz header")
    magic, version, count, sh_degree, fractional_bits, flags, _ = HEADER.unpack_from(head)
    if magic != MAGIC:
        raise SplatFormatError(path, f"not an spz file (magic {magic:#010x}, expected {MAGIC:#010x} 'NGSP')")
    if version not in GZIP_VERSIONS:
        raise SplatFormatError(path, f"unsupported spz version {version} in a gzip stream (versions 2 and 3 are)")
    header = _checked_header(path, _Header(version, count, sh_degree, fractional_bits, flags), len(data))
    sizes = _block_sizes(header)
    need = sum(sizes.values())
    payload = inflate(path, data, HEADER.size + need + (0 if flags & FLAG_EXTENSIONS else 1))
    have = len(payload) - HEADER.size
    if have < need:
        raise SplatFormatError(
            path,
            f"truncated: the header promises {count} points ({need} bytes of data) but only {have} bytes follow "
            "(truncated file or wrong point count)",
        )
    if have > need:
        raise SplatFormatError(path, f"more data than the {need} bytes that the header's {count} points need")
    blocks, offset = {}, HEADER.size
    for name, size in sizes.items():
        blocks[name] = np.frombuffer(payload, np.uint8, size, offset)
        offset += size
    return header, blocks


def _zstd_blocks(path: PathLike, data: bytes) -> tuple[_Header, dict[str, np.ndarray]]:
    """Header and attribute blocks of a version 4 file: a plain 32-byte header, a table of contents, then
    one zstd stream per attribute."""
    if len(data) < HEADER_V4.size:
        raise SplatFormatError(path, f"truncated: {len(data)} bytes, less than the {HEADER_V4.size}-byte spz header")
    _, version, count, sh_degree, fractional_bits, flags, n_streams, toc = HEADER_V4.unpack_from(data)
    if version != ZSTD_VERSION:
        raise SplatFormatError(path, f"unsupported spz version {version} (this reader reads versions 2, 3 and 4)")
    header = _checked_header(path, _Header(version, count, sh_degree, fractional_bits, flags), len(data))
    sizes = _block_sizes(header)
    names = [name for name in sizes if name != "sh" or sh_degree > 0]
    if n_streams != len(names):
        raise SplatFormatError(path, f"{n_streams} data streams, expected {len(names)} for SH degree {sh_degree}")
    offset = toc + 16 * n_streams
    if toc < HEADER_V4.size or offset > len(data):
        raise SplatFormatError(
            path,
            f"the table of contents ({16 * n_streams} bytes at offset {toc}) does not lie between the "
            f"{HEADER_V4.size}-byte header and the end of the {len(data)}-byte file",
        )
    table = np.frombuffer(data, "<u8", 2 * n_streams, toc).reshape(n_streams, 2)
    zstd = _zstandard(path)
    blocks = {"sh": np.empty(0, np.uint8)}
    for name, (packed, size) in zip(names, table.tolist()):
        if size != sizes[name]:
            raise SplatFormatError(
                path, f"the {name} stream holds {size} bytes, not the {sizes[name]} of the header's {count} points"
            )
        if offset + packed > len(data):
            raise SplatFormatError(path, f"truncated: the {name} stream ends beyond the end of the file")
        blocks[name] = _unzstd(path, zstd, data[offset : offset + packed], size, name)
        offset += packed
    return header, blocks


def _zstandard(path: PathLike):
    """The ``zstandard`` module (Blender bundles it), or an error saying version 4 files need it."""
    try:
        import zstandard
    except ImportError:
        raise SplatFormatError(
            path, "spz version 4 is zstd-compressed and needs the zstandard package (pip install zstandard)"
        ) from None
    return zstandard


def _unzstd(path: PathLike, zstd, packed: bytes, size: int, name: str) -> np.ndarray:
    """One zstd stream decompressed to exactly ``size`` bytes (never more: no zstd bombs)."""
    try:
        with zstd.ZstdDecompressor().stream_reader(io.BytesIO(packed), read_across_frames=True) as reader:
            out = reader.read(size + 1)
    except zstd.ZstdError as exc:
        raise SplatFormatError(path, f"the {name} stream is corrupt ({exc})") from None
    if len(out) != size:
        raise SplatFormatError(path, f"the {name} stream decompresses to {len(out)} bytes, not {size}")
    return np.frombuffer(out, np.uint8)


def _checked_header(path: PathLike, header: _Header, file_size: int) -> _Header:
    """The header, once its SH degree is one the engine holds and its point count fits in the file's budget."""
    if header.sh_degree > 3:
        raise SplatFormatError(path, f"SH degree {header.sh_degree} is not supported (0 to 3)")
    what = f"{header.count} points of SH degree {header.sh_degree}"
    problem = codec.over_budget(sum(_block_sizes(header).values()), file_size, what)
    if problem:
        raise SplatFormatError(path, problem)
    return header


def _block_sizes(header: _Header) -> dict[str, int]:
    """Bytes of each attribute block, in file order."""
    n = header.count
    return {
        "positions": 9 * n,
        "alphas": n,
        "colors": 3 * n,
        "scales": 3 * n,
        "rotations": (3 if header.version == 2 else 4) * n,
        "sh": 3 * ((header.sh_degree + 1) ** 2 - 1) * n,
    }


def _decode_positions(raw: np.ndarray, fractional_bits: int) -> np.ndarray:
    """(N, 3) positions from signed 24-bit little-endian fixed point."""
    b = raw.reshape(-1, 3, 3).astype(np.int32)
    fixed = b[..., 0] | (b[..., 1] << 8) | (b[..., 2] << 16)
    return ((fixed ^ 0x800000) - 0x800000) * np.ldexp(1.0, -fractional_bits)


def _decode_rotations_v2(raw: np.ndarray) -> np.ndarray:
    """(N, 4) w, x, y, z from version 2's x, y, z bytes (w >= 0 from the unit norm)."""
    xyz = raw.reshape(-1, 3) / 127.5 - 1.0
    w = np.sqrt(np.maximum(0.0, 1.0 - np.sum(xyz * xyz, axis=1)))
    return np.concatenate([w[:, None], xyz], axis=1)


def _decode_rotations_v3(raw: np.ndarray) -> np.ndarray:
    """(N, 4) w, x, y, z from version 3's smallest-three u32s (components stored in x, y, z, w order)."""
    packed = raw.view("<u4").astype(np.int64)
    fields = (packed[:, None] >> np.array([20, 10, 0])) & 0x3FF
    values = _SQRT_HALF * (fields & 0x1FF) / 511.0 * np.where(fields & 0x200, -1.0, 1.0)
    return from_smallest_three(packed >> 30, values)[:, [3, 0, 1, 2]]


def write_spz(
    path: PathLike,
    scene: GaussianScene | SplatArrays,
    *,
    version: int = 3,
    fractional_bits: int | None = None,
    sh_bits: tuple[int, int] = SH_BITS,
) -> list[str]:
    """Write a scene as SPZ atomically; return one-line notes on what the format did not keep.

    ``fractional_bits``: position steps of 2^-bits; None keeps the reference writer's 12, fewer when a
    position lies beyond +-2048. ``sh_bits``: the bits kept of SH band 1 and of bands 2-3 (1-8; the
    reference writer's 5 and 4 by default). ``SplatFormatError`` naming ``path`` for NaN/Inf values or positions
    out of range; ``ValueError`` for bad options.
    """
    if version not in GZIP_VERSIONS:
        raise ValueError(f"spz version must be one of {GZIP_VERSIONS} (version 4 is read only), got {version}")
    if not all(1 <= bits <= 8 for bits in sh_bits):
        raise ValueError(f"sh_bits must be two bit counts from 1 to 8, got {sh_bits}")
    arrays = as_arrays(scene)
    require_finite(path, arrays, "spz")
    bits = _fractional_bits(path, np.asarray(arrays.means, np.float64), fractional_bits)
    payload = _payload(arrays, version, bits, sh_bits)
    atomic_write(Path(path), gzip.compress(payload, compresslevel=6, mtime=0))
    return dropped_notes(arrays, "spz", 3) + _clipping_notes(arrays)


def _payload(arrays: SplatArrays, version: int, bits: int, sh_bits: tuple[int, int]) -> bytes:
    """The uncompressed file: header, then each attribute block."""
    degree = sh_degree_from_rest(int(arrays.sh_rest.shape[1]))
    quats = arrays.quats
    blocks = [
        np.frombuffer(HEADER.pack(MAGIC, version, len(arrays), degree, bits, 0, 0), np.uint8),
        _encode_positions(np.asarray(arrays.means, np.float64), bits),
        _quantise(sigmoid(arrays.opacity_logits) * 255.0),
        _quantise(np.asarray(arrays.sh_dc, np.float64) * (COLOR_SCALE * 255.0) + 127.5),
        _quantise((np.asarray(arrays.log_scales, np.float64) + LOG_SCALE_OFFSET) * LOG_SCALE_STEPS),
        _encode_rotations_v2(quats) if version == 2 else _encode_rotations_v3(quats),
        _encode_sh(np.asarray(arrays.sh_rest, np.float64), sh_bits),
    ]
    return b"".join(block.tobytes() for block in blocks)


def _clipping_notes(arrays: SplatArrays) -> list[str]:
    """A note per field with values beyond the range its bytes can express (more than half a step out)."""
    colour = 0.5 / COLOR_SCALE
    ranges = {
        "DC colour coefficients to +-3.33 (colour -0.44..1.44)": (
            arrays.sh_dc,
            -colour,
            colour,
            1 / (255 * COLOR_SCALE),
        ),
        "log scales to -10..5.94": (
            arrays.log_scales,
            -LOG_SCALE_OFFSET,
            255 / LOG_SCALE_STEPS - LOG_SCALE_OFFSET,
            1 / LOG_SCALE_STEPS,
        ),
        "SH band 1-3 coefficients to -1..0.99": (arrays.sh_rest, -1.0, 127 / 128, 1 / 128),
    }
    notes = []
    for what, (values, low, high, step) in ranges.items():
        count = int(np.count_nonzero((values < low - step / 2) | (values > high + step / 2)))
        if count:
            notes.append(f"spz clips {what}: {count} values clipped")
    return notes


def _fractional_bits(path: PathLike, means: np.ndarray, wanted: int | None) -> int:
    """``wanted`` (None: the reference writer's 12, or fewer when the positions need the range), checked to
    hold every position in 24-bit fixed point."""
    most = _most_fractional_bits(path, means)
    if wanted is None:
        return min(REFERENCE_FRACTIONAL_BITS, most)
    if not 0 <= wanted <= most:
        raise ValueError(f"fractional_bits={wanted} cannot hold the scene's positions (use 0 to {most})")
    return wanted


def _most_fractional_bits(path: PathLike, means: np.ndarray) -> int:
    """The most fractional bits (up to 30) whose 24-bit fixed point holds every position; an error naming the
    file to be written when none does."""
    largest = float(np.max(np.abs(means))) if means.size else 0.0
    bits = MAX_FRACTIONAL_BITS
    if largest > 0.0:
        bits = min(bits, int(np.floor(np.log2(_INT24_MAX / largest))))
    while bits >= 0 and np.round(largest * 2.0**bits) > _INT24_MAX:
        bits -= 1
    if bits < 0:
        raise SplatFormatError(path, f"positions reach {largest:g}, beyond the +-{_INT24_MAX} units spz can store")
    return bits


def _quantise(values: np.ndarray) -> np.ndarray:
    """Values rounded to the nearest byte, clamped to 0..255."""
    return np.clip(np.round(values), 0, 255).astype(np.uint8)


def _encode_positions(means: np.ndarray, bits: int) -> np.ndarray:
    """(N, 9) bytes: signed 24-bit little-endian fixed point with ``bits`` fractional bits."""
    fixed = np.round(means * 2.0**bits).astype("<i4")
    return fixed.view(np.uint8).reshape(-1, 3, 4)[..., :3]


def _encode_rotations_v2(quats: np.ndarray) -> np.ndarray:
    """(N, 3) bytes: x, y, z of the unit quaternion with w >= 0."""
    return _quantise((canonical_quats(quats)[:, 1:] + 1.0) * 127.5)


def _encode_rotations_v3(quats: np.ndarray) -> np.ndarray:
    """(N,) little-endian u32s: the smallest three components and the largest one's index (x, y, z, w order)."""
    largest, others = smallest_three(canonical_quats(quats)[:, [1, 2, 3, 0]])
    magnitude = np.minimum(np.round(np.abs(others) / _SQRT_HALF * 511.0), 511).astype(np.int64)
    fields = magnitude | np.where(others < 0.0, 0x200, 0)
    packed = (largest.astype(np.int64) << 30) | (fields[:, 0] << 20) | (fields[:, 1] << 10) | fields[:, 2]
    return packed.astype("<u4")


def _encode_sh(sh_rest: np.ndarray, sh_bits: tuple[int, int]) -> np.ndarray:
    """(N, K, 3) bytes v * 128 + 128, band 1 rounded to ``sh_bits[0]`` bits and bands 2-3 to ``sh_bits[1]``."""
    bucket = np.full((sh_rest.shape[1], 1), 2.0 ** (8 - sh_bits[1]))
    bucket[:3] = 2.0 ** (8 - sh_bits[0])
    fine = np.round(sh_rest * 128.0 + 128.0)
    return np.clip(np.floor((fine + np.floor(bucket / 2)) / bucket) * bucket, 0, 255).astype(np.uint8)
