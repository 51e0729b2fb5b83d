"""Every splat file the tools read and write: a file's format from its content, one reader and one writer
entry point, and what each format keeps. numpy only (Blender imports splats before torch is installed).

Formats: INRIA PLY (``.ply``), PlayCanvas compressed PLY (``.compressed.ply``) and SOG (``.sog``, or a
folder / ``meta.json`` unpacked from one), Niantic SPZ (``.spz``) and antimatter15 ``.splat``. A file's
content decides its format (magic bytes, the PLY header's elements); only headerless ``.splat`` files are
known by their extension.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from ..atomic import ZIP_MAGIC, read_head
from ..errors import SplatFormatError
from .arrays import SplatArrays
from .codec import PathLike, as_arrays
from .compressed_ply import is_compressed_ply, read_compressed_ply, write_compressed_ply
from .ply import read_ply_arrays
from .ply_header import read_ply_header
from .ply_write import write_ply
from .sog import read_sog
from .splat import read_splat, write_splat
from .spz import MAGIC_BYTES as SPZ_MAGIC
from .spz import read_spz, write_spz

if TYPE_CHECKING:
    from .gaussians import GaussianScene

PLY, COMPRESSED_PLY, SOG, SPZ, SPLAT = "ply", "compressed-ply", "sog", "spz", "splat"
SOG_META = "meta.json"


@dataclass(frozen=True)
class SplatFormat:
    """A splat file format: its names and what it keeps (``WRITERS`` says which ones the tools write)."""

    label: str
    extensions: tuple[str, ...]
    keeps: str


FORMATS: dict[str, SplatFormat] = {
    PLY: SplatFormat("INRIA PLY", (".ply",), "everything: float32 values, SH degree 0-3, extra properties"),
    COMPRESSED_PLY: SplatFormat(
        "PlayCanvas compressed PLY",
        (".compressed.ply",),
        "positions and log scales to 11/10/11 bits of each 256-splat chunk's range, rotations to 3 x 10 bits, "
        "colour to 8 bits of the chunk's range, opacity to 8 bits, SH degree 0-3 to 8 bits (within +-4); no extra "
        "properties",
    ),
    SOG: SplatFormat(
        "PlayCanvas SOG",
        (".sog", SOG_META),
        "positions to 16 bits per axis (log-mapped), log scales, colours and SH bands through 256-entry codebooks, "
        "opacity to 8 bits, rotations to 3 x 8 bits; SH degree 0-3; read only",
    ),
    SPZ: SplatFormat(
        "Niantic SPZ",
        (".spz",),
        "positions to 24-bit fixed point (1/4096), log scales, colour and opacity to 8 bits, rotations to 3 x 10 "
        "bits (3 x 8 in version 2), SH band 1 to 5 bits and bands 2-3 to 4 bits; no extra properties; reads "
        "versions 2-4, writes 3",
    ),
    SPLAT: SplatFormat(
        "antimatter15 .splat",
        (".splat",),
        "positions and scales as float32, colour, opacity and rotations to 8 bits; SH degree 0 only; no extra "
        "properties",
    ),
}
"""The formats, by name; the README's table and ``info`` say the same from here."""

READERS: dict[str, Callable[..., SplatArrays]] = {
    PLY: read_ply_arrays,
    COMPRESSED_PLY: read_compressed_ply,
    SOG: read_sog,
    SPZ: read_spz,
    SPLAT: read_splat,
}
WRITERS: dict[str, Callable[[PathLike, object], list[str] | None]] = {
    PLY: write_ply,
    COMPRESSED_PLY: write_compressed_ply,
    SPZ: write_spz,
    SPLAT: write_splat,
}
WRITE_EXTENSIONS = tuple(ext for fmt in WRITERS for ext in FORMATS[fmt].extensions)
"""File name endings the writers take, in ``WRITERS``' order (``.compressed.ply`` whole)."""
READ_EXTENSIONS = tuple(
    sorted({"." + ext.rsplit(".", 1)[1] for fmt in FORMATS.values() for ext in fmt.extensions if ext != SOG_META})
)
"""File name endings the importers offer (``.compressed.ply`` is a ``.ply``; ``meta.json`` is not offered)."""
KIND_BY_ENDING = {".ply": "PLY", ".sog": "SOG", ".spz": "SPZ"}
"""What an error calls a file whose name claims a format its content does not have."""


def detect_format(path: PathLike) -> str:
    """The format of a splat file (or SOG folder) from its content; SplatFormatError when it is none of them."""
    path = Path(path)
    if path.is_dir():
        if (path / SOG_META).is_file():
            return SOG
        raise SplatFormatError(path, f"is a directory, and not an unpacked SOG scene: it holds no {SOG_META}")
    head = _head(path)
    if head.startswith((b"ply\n", b"ply\r\n")):
        return COMPRESSED_PLY if is_compressed_ply(read_ply_header(path)) else PLY
    if head.startswith(ZIP_MAGIC) or (path.name == SOG_META and head.lstrip().startswith(b"{")):
        return SOG
    if head.startswith((b"\x1f\x8b", SPZ_MAGIC)):  # versions 2-3 are gzip streams, version 4 starts bare
        return SPZ
    if path.suffix.lower() == ".splat":
        return SPLAT
    kind = KIND_BY_ENDING.get(path.suffix.lower(), "splat")
    raise SplatFormatError(
        path,
        f"not a {kind} file (it starts with {head[:8]!r}; these tools read INRIA and compressed PLY, SOG, SPZ "
        "and .splat files)",
    )


def _head(path: Path, size: int = 16) -> bytes:
    """The first bytes of a file; a missing or unreadable one is an error naming it."""
    try:
        return read_head(path, size)
    except FileNotFoundError:
        raise SplatFormatError(path, "no such file") from None
    except OSError as exc:
        raise SplatFormatError(path, f"cannot read the file ({exc.strerror or exc})") from None


def read_splats(path: PathLike, *, drop_invalid: bool = False, **options: object) -> SplatArrays:
    """Load any splat file as numpy arrays (``options``: format-specific, e.g. SOG's ``decode_webp``)."""
    fmt = detect_format(path)
    try:
        if fmt == SOG:
            return read_sog(path, drop_invalid=drop_invalid, **options)
        return READERS[fmt](path, drop_invalid=drop_invalid)
    except MemoryError:  # what the headers declare fits their budget, yet not in this machine's memory
        raise SplatFormatError(
            path, f"too large to decode in the memory available (a {FORMATS[fmt].label} file)"
        ) from None


def read_scene(path: PathLike, *, drop_invalid: bool = False) -> GaussianScene:
    """Load any splat file as a ``GaussianScene`` of float32 tensors."""
    from .gaussians import GaussianScene

    return GaussianScene.from_arrays(read_splats(path, drop_invalid=drop_invalid))


def output_format(path: PathLike, fmt: str | None = None) -> str:
    """The format to write ``path`` in: ``fmt``, else the one its name ends with; an error for one we only read,
    and for a name that ends with none (``out.txt`` would hold a PLY its name hides)."""
    writable = ", ".join(WRITE_EXTENSIONS)
    if fmt is None:
        name = os.fspath(path).lower()
        fmt = next((f for f in (COMPRESSED_PLY, PLY, SPZ, SPLAT, SOG) if name.endswith(FORMATS[f].extensions)), None)
        if fmt is None:
            raise SplatFormatError(path, f"is not a splat file name; end it with one of {writable}")
    if fmt not in FORMATS:
        raise ValueError(f"unknown splat format {fmt!r}; choose one of {', '.join(FORMATS)}")
    if fmt not in WRITERS:
        raise SplatFormatError(path, f"{FORMATS[fmt].label} is read only here; write one of {writable}")
    if fmt == SPLAT and not os.fspath(path).lower().endswith(FORMATS[SPLAT].extensions):
        raise SplatFormatError(
            path, "a .splat file is known by its name alone (it has no signature): end it with .splat"
        )
    return fmt


def write_splats(path: PathLike, scene: GaussianScene | SplatArrays, fmt: str | None = None) -> list[str]:
    """Write a scene (atomically) in ``fmt`` or the format its file name says; one-line notes on what the
    format could not keep (SH bands, extra properties), empty when nothing was lost."""
    fmt = output_format(path, fmt)
    notes = WRITERS[fmt](path, scene if fmt == PLY else as_arrays(scene))
    return list(notes or [])
