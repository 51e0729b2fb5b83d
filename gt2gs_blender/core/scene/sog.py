"""Read PlayCanvas SOG scenes (version 2): a ``.sog`` zip, or the same files unpacked beside a ``meta.json``.

Layout. ``meta.json`` gives ``version`` (2), ``count`` (N) and, per attribute, the WebP images that hold
it (``files``, names relative to meta.json) with what is needed to decode them. Every per-Gaussian image
is lossless RGBA, at least N pixels; Gaussian i is pixel i in row-major order (row i // width, column
i % width), and pixels past N are padding. The writer sorts the Gaussians in Morton order, so a SOG's
order is not its source's.

- ``means``: ``means_l`` and ``means_u`` hold the low and high byte of a 16-bit value per axis (R, G, B
  = x, y, z). The value spans ``mins``..``maxs`` (per axis) of the log-transformed position
  sign(x)·ln(1 + |x|), so positions keep about 1/65535 of that span, relatively finer near the origin.
- ``scales``: R, G, B index the 256-entry ``codebook`` of log scales (shared by the three axes, 1D
  k-means), so a scale keeps the codebook's spacing around it.
- ``quats``: smallest-three. A holds 252 + the index (w, x, y, z) of the largest component, which is
  dropped and rebuilt as the positive root of the unit norm; R, G, B hold the other three in order,
  times √2, mapped from -1..1 to 0..255 (steps of √2/255 ≈ 0.0055 per component). Another alpha value
  decodes as the identity, as splat-transform reads it.
- ``sh0``: R, G, B index the 256-entry ``codebook`` of DC SH coefficients (shared by the channels); A is
  the activated opacity in 1/255 steps (the logit of 0 or 1 is clipped as in ``codec.logit``).
- ``shN`` (optional): ``bands`` (1-3) and a palette of ``count`` SH vectors (k-means over the Gaussians,
  so higher bands are shared and only approximate). ``shN_labels`` holds each Gaussian's palette index
  in R (low byte) and G (high byte). ``shN_centroids`` is 64 palette entries per row, each ``coeffs``
  pixels wide (coefficient j of entry e at column (e % 64)·coeffs + j, row e // 64), whose R, G, B
  index the 256-entry ``codebook`` of SH values for the three colour channels. A label past the palette
  is an error here (splat-transform reads zeros).

Version 1 (no ``version``: per-channel min/max instead of codebooks) is not read. Entries are checked
against ``codec.MAX_DECOMPRESSED`` before they are inflated, and the pixels the WebP headers declare against
``codec.over_budget`` before any image is decoded. numpy only: the WebP decoder is a parameter
(``decode_webp``); the default one imports OpenCV when it is called, and Blender passes its own.
"""

from __future__ import annotations

import io
import json
import math
import struct
import zipfile
from collections.abc import Callable
from pathlib import Path, PurePosixPath
from typing import Any

import numpy as np

from ..errors import SplatFormatError
from . import codec
from .arrays import SplatArrays
from .codec import PathLike, canonical_quats, from_smallest_three, logit, make_arrays, read_bytes

WebpDecoder = Callable[[bytes, str], "np.ndarray | None"]
"""``decode_webp(data, name)``: the (H, W, 4) uint8 RGBA pixels of a WebP file, or None if it does not decode."""

VERSION = 2
META_NAME = "meta.json"
CODEBOOK_SIZE = 256
PALETTE_ROW = 64
"""Palette entries per row of the ``shN_centroids`` image."""
SH_COEFFS = {1: 3, 2: 8, 3: 15}
"""Coefficients per colour channel beyond the DC term, by SH degree (``shN.bands``)."""
WEBP_HEADER = 30
"""Bytes of a WebP file that hold its size, whichever its kind."""
QUAT_TAG = 252
"""Alpha of a ``quats`` pixel: QUAT_TAG + the index (w, x, y, z) of the dropped largest component."""
"""The components R, G, B hold, by dropped component."""


def read_sog(path: PathLike, *, decode_webp: WebpDecoder | None = None, drop_invalid: bool = False) -> SplatArrays:
    """Load a SOG scene (``.sog`` zip, ``meta.json`` or a folder holding it) as checked ``SplatArrays``."""
    source = _open_source(Path(path))
    meta = _parse_meta(source)
    decode = decode_webp or decode_webp_cv2
    count, sh = meta["count"], meta.get("shN")
    if count == 0:
        return _empty(source, SH_COEFFS[sh["bands"]] if sh else 0, drop_invalid)
    _check_image_budget(source, _names(meta))
    means_low, means_high = (_pixels(source, name, decode, count) for name in meta["means"]["files"])
    sh0 = _pixels(source, meta["sh0"]["files"][0], decode, count)
    scales = _pixels(source, meta["scales"]["files"][0], decode, count)
    return make_arrays(
        source.path,
        means=_decode_means(means_low, means_high, meta["means"]),
        quats=_decode_quats(_pixels(source, meta["quats"]["files"][0], decode, count)),
        log_scales=_codebook(meta["scales"])[scales[:, :3]],
        opacity_logits=logit(sh0[:, 3] / 255.0),
        sh_dc=_codebook(meta["sh0"])[sh0[:, :3]],
        sh_rest=_decode_sh_rest(source, sh, decode, count) if sh else np.zeros((count, 0, 3), np.float32),
        drop_invalid=drop_invalid,
    )


def _empty(source: _Source, k: int, drop_invalid: bool) -> SplatArrays:
    """The arrays of a SOG with no Gaussians (its images are not decoded)."""
    rows = np.zeros((0, 3))
    return make_arrays(
        source.path,
        means=rows,
        quats=np.zeros((0, 4)),
        log_scales=rows,
        opacity_logits=np.zeros(0),
        sh_dc=rows,
        sh_rest=np.zeros((0, k, 3)),
        drop_invalid=drop_invalid,
    )


def decode_webp_cv2(data: bytes, name: str) -> np.ndarray | None:
    """The (H, W, 4) uint8 RGBA pixels of a WebP file, decoded by OpenCV (None if it does not decode)."""
    import cv2

    image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    if image is None:
        return None
    if image.ndim == 2:
        return cv2.cvtColor(image, cv2.COLOR_GRAY2RGBA)
    if image.shape[2] == 3:
        return cv2.cvtColor(image, cv2.COLOR_BGR2RGBA)
    return cv2.cvtColor(image, cv2.COLOR_BGRA2RGBA)


class _Source:
    """The files of one SOG: entries of a zip or files in a folder, by name relative to meta.json."""

    def __init__(self, path: Path, *, archive: zipfile.ZipFile | None = None, folder: Path | None = None) -> None:
        self.path = path
        self.archive = archive
        self.folder = folder

    def error(self, name: str, problem: str) -> SplatFormatError:
        """An error naming the file (a zip entry is named after the zip's path)."""
        if self.archive is not None:
            return SplatFormatError(self.path, f"{name}: {problem}")
        return SplatFormatError(self.path if name == META_NAME else self.folder / name, problem)

    def head(self, name: str, size: int) -> bytes:
        """The first ``size`` bytes of a file named in meta.json (nothing else is read or inflated)."""
        self._check_name(name)
        try:
            if self.archive is None:
                with open(self.folder / name, "rb") as f:
                    return f.read(size)
            with self.archive.open(_entry(self, name)) as f:
                return f.read(size)
        except ZIP_ERRORS as exc:
            raise self.error(name, f"cannot be read ({exc})") from None

    def stored_size(self, name: str) -> int:
        """The bytes a file named in meta.json takes in the zip or on disk."""
        if self.archive is not None:
            return _entry(self, name).compress_size
        try:
            return (self.folder / name).stat().st_size
        except OSError as exc:
            raise self.error(name, f"cannot be read ({exc.strerror or exc})") from None

    def read(self, name: str) -> bytes:
        """The bytes of a file named in meta.json."""
        self._check_name(name)
        if self.archive is None:
            return read_bytes(self.folder / name)
        return _read_entry(self, name)

    def _check_name(self, name: str) -> None:
        """A name in meta.json must be a plain name beside it (no absolute path, no ``..``)."""
        parts = PurePosixPath(name).parts
        if not name or name.startswith("/") or ".." in parts or "\\" in name:
            raise self.error(META_NAME, f"file name {name!r} is not a plain name beside meta.json")


ZIP_ERRORS = (zipfile.BadZipFile, OSError, EOFError, NotImplementedError, RuntimeError, ValueError)
"""What reading a damaged zip entry raises: a bad archive, a truncated stream, a compression method zipfile
does not implement (NotImplementedError), an encrypted entry (RuntimeError), a corrupt deflate stream."""


def _entry(source: _Source, name: str) -> zipfile.ZipInfo:
    """A zip entry by name; a missing one is an error naming it."""
    try:
        return source.archive.getinfo(name)
    except KeyError:
        raise source.error(name, "missing from the zip") from None


def _read_entry(source: _Source, name: str) -> bytes:
    """A zip entry's bytes, refusing one that declares more than ``codec.MAX_DECOMPRESSED`` (a zip bomb)."""
    info = _entry(source, name)
    limit = codec.MAX_DECOMPRESSED
    if info.file_size > limit:
        raise source.error(name, f"declares {info.file_size} bytes uncompressed, over the {limit}-byte limit")
    try:
        return source.archive.read(info)
    except ZIP_ERRORS as exc:
        raise source.error(name, f"cannot be extracted ({exc})") from None


def _open_source(path: Path) -> _Source:
    """The SOG at ``path``: a folder holding meta.json, a meta.json file or a zip."""
    if path.is_dir():
        return _Source(path / META_NAME, folder=path)
    data = read_bytes(path)
    if not data.startswith(b"PK"):
        if path.suffix.lower() == ".sog":
            raise SplatFormatError(path, "not a zip archive: not a SOG file")
        return _Source(path, folder=path.parent)
    try:
        archive = zipfile.ZipFile(io.BytesIO(data))
    except ZIP_ERRORS as exc:  # a central directory asking for a zip version zipfile lacks: NotImplementedError
        raise SplatFormatError(path, f"not a readable zip archive ({exc})") from None
    if META_NAME not in archive.namelist():
        raise SplatFormatError(path, f"the zip holds no {META_NAME}: not a SOG file")
    return _Source(path, archive=archive)


def _parse_meta(source: _Source) -> dict[str, Any]:
    """meta.json, parsed and checked: version 2 with every field the reader needs."""
    data = read_bytes(source.path) if source.archive is None else _read_entry(source, META_NAME)
    try:
        meta = json.loads(data)
    except (UnicodeDecodeError, ValueError) as exc:
        raise source.error(META_NAME, f"is not JSON ({exc})") from None
    except RecursionError:
        raise source.error(META_NAME, "is nested too deeply to be a SOG's meta.json") from None
    if not isinstance(meta, dict):
        raise source.error(META_NAME, "is not a JSON object")
    version = meta.get("version")
    if version is None:
        raise source.error(META_NAME, "has no version: a version 1 SOG, not supported (re-export as version 2)")
    if version != VERSION or isinstance(version, bool):
        raise source.error(META_NAME, f"unsupported SOG version {version!r} (this reader reads version {VERSION})")
    count = meta.get("count")
    if not _is_int(count) or count < 0:
        raise source.error(META_NAME, f"count {count!r} is not a non-negative integer")
    _check_section(source, meta, "means", files=2)
    for key in ("mins", "maxs"):
        _check_numbers(source, f"means.{key}", meta["means"].get(key), 3)
    _check_section(source, meta, "quats", files=1)
    for key in ("scales", "sh0"):
        _check_section(source, meta, key, files=1)
        _check_numbers(source, f"{key}.codebook", meta[key].get("codebook"), CODEBOOK_SIZE)
    if meta.get("shN") is not None:
        _check_sh(source, meta)
    return meta


def _check_sh(source: _Source, meta: dict[str, Any]) -> None:
    """Check the ``shN`` section; one with 0 bands is dropped (no higher SH bands)."""
    _check_section(source, meta, "shN", files=2)
    sh = meta["shN"]
    bands = sh.get("bands")
    if bands == 0 and not isinstance(bands, bool):
        meta["shN"] = None
        return
    if not _is_int(bands) or bands not in SH_COEFFS:
        raise source.error(META_NAME, f"shN.bands {bands!r} is not 1, 2 or 3")
    if not _is_int(sh.get("count")) or sh["count"] < 1:
        raise source.error(META_NAME, f"shN.count {sh.get('count')!r} is not a positive integer")
    _check_numbers(source, "shN.codebook", sh.get("codebook"), CODEBOOK_SIZE)


def _check_section(source: _Source, meta: dict[str, Any], key: str, *, files: int) -> None:
    """A section of meta.json must be an object naming ``files`` image files."""
    section = meta.get(key)
    if not isinstance(section, dict):
        raise source.error(META_NAME, f"has no {key!r} section")
    names = section.get("files")
    if not isinstance(names, list) or len(names) != files or not all(isinstance(n, str) for n in names):
        raise source.error(META_NAME, f"{key}.files must list {files} file name(s), got {names!r}")


def _check_numbers(source: _Source, field: str, values: object, length: int) -> None:
    """A list of ``length`` numbers (a codebook, min or max)."""
    if not isinstance(values, list) or not all(_is_number(v) for v in values):
        raise source.error(META_NAME, f"{field} is missing or not a list of numbers")
    if len(values) != length:
        raise source.error(META_NAME, f"{field} has {len(values)} entries, expected {length}")


def _is_int(value: object) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _is_number(value: object) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _names(meta: dict[str, Any]) -> list[str]:
    """Every image file meta.json names, in the order they are decoded."""
    sections = ("means", "sh0", "scales", "quats", "shN")
    return [name for key in sections if meta.get(key) for name in meta[key]["files"]]


def webp_size(data: bytes) -> tuple[int, int] | None:
    """Width and height that a WebP file's header declares (lossy, lossless or extended), read without
    decoding it; None when ``data`` does not start as a WebP file."""
    if len(data) < WEBP_HEADER or data[:4] != b"RIFF" or data[8:12] != b"WEBP":
        return None
    kind = data[12:16]
    if kind == b"VP8 ":
        width, height = struct.unpack_from("<HH", data, 26)
        return width & 0x3FFF, height & 0x3FFF
    if kind == b"VP8L":
        (bits,) = struct.unpack_from("<I", data, 21)
        return (bits & 0x3FFF) + 1, ((bits >> 14) & 0x3FFF) + 1
    if kind == b"VP8X":
        return int.from_bytes(data[24:27], "little") + 1, int.from_bytes(data[27:30], "little") + 1
    return None


def _check_image_budget(source: _Source, names: list[str]) -> None:
    """Refuse images whose headers declare more pixels than the SOG's size can hold, before any is decoded."""
    sizes = {name: webp_size(source.head(name, WEBP_HEADER)) for name in names}
    declared = sum(4 * width * height for width, height in filter(None, sizes.values()))
    what = ", ".join(f"{name} {size[0]}x{size[1]}" for name, size in sizes.items() if size)
    stored = sum(source.stored_size(name) for name in names)
    problem = codec.over_budget(declared, stored, f"the RGBA pixels of {what}")
    if problem:
        raise source.error(META_NAME, problem)


def _image(source: _Source, name: str, decode: WebpDecoder) -> np.ndarray:
    """A decoded image as (H, W, 4) uint8; a decoder that fails or returns None is an error naming the file."""
    data = source.read(name)
    try:
        image = decode(data, name)
    except Exception as exc:
        raise source.error(name, f"does not decode as WebP ({type(exc).__name__}: {exc})") from None
    if image is None:
        raise source.error(name, "does not decode as WebP")
    image = np.asarray(image)
    if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] not in (3, 4):
        raise source.error(name, f"decoded to {image.dtype} pixels of shape {image.shape}, not (H, W, 4) uint8")
    if image.shape[2] == 3:
        image = np.concatenate([image, np.full((*image.shape[:2], 1), 255, np.uint8)], axis=2)
    return image


def _pixels(source: _Source, name: str, decode: WebpDecoder, count: int) -> np.ndarray:
    """The first ``count`` pixels of a per-Gaussian image, (count, 4) uint8 in row-major order."""
    image = _image(source, name, decode)
    height, width = image.shape[:2]
    if width * height < count:
        raise source.error(name, f"is {width}x{height} pixels, too small for {count} Gaussians")
    return image.reshape(-1, 4)[:count]


def _codebook(section: dict[str, Any]) -> np.ndarray:
    """A 256-entry codebook as float32 (the precision it was written in)."""
    return np.asarray(section["codebook"], np.float64).astype(np.float32)


def _decode_means(low: np.ndarray, high: np.ndarray, section: dict[str, Any]) -> np.ndarray:
    """Positions from the 16-bit log-space values (low, high bytes in R, G, B)."""
    q = low[:, :3].astype(np.float64) + 256.0 * high[:, :3]
    mins = np.asarray(section["mins"], np.float64)
    spans = np.asarray(section["maxs"], np.float64) - mins
    spans = np.where(spans == 0.0, 1.0, spans)  # as splat-transform reads a flat axis (written as 0: its minimum)
    v = mins + spans * (q / 65535.0)
    return np.sign(v) * np.expm1(np.abs(v))


def _decode_quats(pixels: np.ndarray) -> np.ndarray:
    """Unit quaternions (w, x, y, z), w >= 0, from smallest-three pixels; a bad tag decodes as the identity."""
    small = (pixels[:, :3] / 255.0 * 2.0 - 1.0) / math.sqrt(2.0)
    dropped = pixels[:, 3].astype(np.int64) - QUAT_TAG
    valid = (dropped >= 0) & (dropped <= 3)
    quats = from_smallest_three(np.where(valid, dropped, 0), small)
    quats[~valid] = (1.0, 0.0, 0.0, 0.0)
    return canonical_quats(quats)


def _decode_sh_rest(source: _Source, sh: dict[str, Any], decode: WebpDecoder, count: int) -> np.ndarray:
    """Higher SH bands (count, K, 3), coefficient-major, from the labels and the palette."""
    k = SH_COEFFS[sh["bands"]]
    names = sh["files"]
    centroids = _image(source, names[0], decode)
    rows, width = centroids.shape[:2]
    if width != PALETTE_ROW * k:
        raise source.error(names[0], f"is {width} pixels wide, expected {PALETTE_ROW * k} for SH degree {sh['bands']}")
    labels = _pixels(source, names[1], decode, count)
    labels = labels[:, 0].astype(np.int64) | (labels[:, 1].astype(np.int64) << 8)
    entries = min(sh["count"], rows * PALETTE_ROW)
    bad = labels >= entries
    if bad.any():
        raise source.error(
            names[1], f"{int(bad.sum())} Gaussians use palette entries past the {entries} the palette holds"
        )
    palette = _codebook(sh)[centroids[:, :, :3].reshape(rows * PALETTE_ROW, k, 3)]
    return palette[labels]
