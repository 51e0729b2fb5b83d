"""The PLY header: format, elements and properties, parsed and checked before any data is read."""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from typing import TYPE_CHECKING, BinaryIO

from ..errors import PlyFormatError

if TYPE_CHECKING:
    import numpy as np


PathLike = str | os.PathLike


HEADER_LIMIT = 64 * 1024
"""Largest header accepted; anything longer is not a real PLY header."""


MAX_ELEMENT_COUNT = 2**32 - 1


FORMATS = {"binary_little_endian": "<", "binary_big_endian": ">", "ascii": "="}


SCALAR_TYPES = {
    "char": "i1",
    "int8": "i1",
    "uchar": "u1",
    "uint8": "u1",
    "short": "i2",
    "int16": "i2",
    "ushort": "u2",
    "uint16": "u2",
    "int": "i4",
    "int32": "i4",
    "uint": "u4",
    "uint32": "u4",
    "float": "f4",
    "float32": "f4",
    "double": "f8",
    "float64": "f8",
}
"""PLY scalar type names (classic and sized aliases) -> numpy type codes."""


TYPE_FOR_CODE = {
    "i1": "char",
    "u1": "uchar",
    "i2": "short",
    "u2": "ushort",
    "i4": "int",
    "u4": "uint",
    "f4": "float",
    "f8": "double",
}
"""numpy type code -> the classic PLY type name written for it (the types PLY can store)."""


def type_code(dtype: np.dtype) -> str:
    """The numpy type code of ``dtype`` without byte order ('f4', 'u1', ...), the key of TYPE_FOR_CODE."""
    return f"{dtype.kind}{dtype.itemsize}"


_PROPERTY_NAME = re.compile(r"[!-~]+")


@dataclass(frozen=True)
class PlyProperty:
    """One property of an element; ``list_count_type`` is set for list properties."""

    name: str
    type: str
    list_count_type: str | None = None


@dataclass(frozen=True)
class PlyElement:
    """An element of the header (``vertex``, ``face``, ...) with its row count and properties."""

    name: str
    count: int
    properties: tuple[PlyProperty, ...]


@dataclass(frozen=True)
class PlyHeader:
    """What a PLY header says, without the data: enough for an ``info`` command."""

    format: str
    vertex_count: int
    properties: tuple[tuple[str, str], ...]
    """Vertex properties (name, PLY type) in file order; list types read ``list <count> <item>``."""
    header_size: int
    """Bytes up to and including the ``end_header`` line."""
    elements: tuple[PlyElement, ...]
    comments: tuple[str, ...]

    @property
    def vertex(self) -> PlyElement:
        return next(e for e in self.elements if e.name == "vertex")


def read_ply_header(path: PathLike) -> PlyHeader:
    """Parse and check the header only (fast, reads at most 64 KiB)."""
    with _open(path) as f:
        return _parse_header(path, _read(path, f, HEADER_LIMIT))


def _open(path: PathLike) -> BinaryIO:
    if os.path.isdir(path):
        raise PlyFormatError(path, "is a directory, not a PLY file")
    try:
        return open(path, "rb")
    except FileNotFoundError:
        raise PlyFormatError(path, "no such file") from None
    except OSError as exc:
        raise PlyFormatError(path, f"cannot be opened ({exc.strerror or exc})") from None


def _read(path: PathLike, f: BinaryIO, size: int) -> bytes:
    try:
        return f.read(size)
    except OSError as exc:
        raise PlyFormatError(path, f"cannot be read ({exc.strerror or exc})") from None


def _parse_header(path: PathLike, data: bytes) -> PlyHeader:
    lines, size = _header_lines(path, data)
    fmt: str | None = None
    elements: list[tuple[str, int, list[PlyProperty]]] = []
    comments: list[str] = []
    for number, line in lines:
        tokens = line.split()
        if not tokens:
            continue
        key = tokens[0]
        if key in ("comment", "obj_info"):
            comments.append(line)
        elif key == "format":
            if fmt is not None:
                raise PlyFormatError(path, f"header line {number}: a second 'format' line")
            fmt = _parse_format(path, number, tokens)
        elif key == "element":
            name, count = _parse_element(path, number, tokens)
            if any(name == e[0] for e in elements):
                raise PlyFormatError(path, f"header line {number}: duplicate element {name!r}")
            elements.append((name, count, []))
        elif key == "property":
            if not elements:
                raise PlyFormatError(path, f"header line {number}: 'property' before any 'element' line")
            prop = _parse_property(path, number, tokens)
            element_name, _, props = elements[-1]
            if any(prop.name == p.name for p in props):
                raise PlyFormatError(
                    path, f"header line {number}: duplicate property {prop.name!r} in element {element_name!r}"
                )
            props.append(prop)
        else:
            raise PlyFormatError(path, f"header line {number}: unknown header keyword {key!r}")
    if fmt is None:
        raise PlyFormatError(path, "the header has no 'format' line")
    parsed = tuple(PlyElement(name, count, tuple(props)) for name, count, props in elements)
    vertex = next((e for e in parsed if e.name == "vertex"), None)
    if vertex is None:
        raise PlyFormatError(path, "the header has no 'element vertex' line (not a point-cloud PLY)")
    return PlyHeader(
        format=fmt,
        vertex_count=vertex.count,
        properties=tuple((p.name, _type_label(p)) for p in vertex.properties),
        header_size=size,
        elements=parsed,
        comments=tuple(comments),
    )


def _header_lines(path: PathLike, data: bytes) -> tuple[list[tuple[int, str]], int]:
    """The header lines after 'ply' (with 1-based line numbers) and the header's size in bytes."""
    if not data:
        raise PlyFormatError(path, "the file is empty (0 bytes), not a PLY file")
    if not (data.startswith(b"ply\n") or data.startswith(b"ply\r\n")):
        raise PlyFormatError(path, "not a PLY file (it does not start with the line 'ply')")
    lines: list[tuple[int, str]] = []
    pos = data.index(b"\n") + 1
    while True:
        end = data.find(b"\n", pos)
        raw = data[pos:] if end < 0 else data[pos:end]
        number = len(lines) + 2
        try:
            line = raw.rstrip(b"\r").decode("ascii")
        except UnicodeDecodeError:
            raise PlyFormatError(path, f"header line {number} is not ASCII text (corrupt header?)") from None
        if line.strip() == "end_header" and (end >= 0 or len(data) < HEADER_LIMIT):
            return lines, len(data) if end < 0 else end + 1
        if end < 0:
            if len(data) >= HEADER_LIMIT:
                raise PlyFormatError(
                    path, f"no 'end_header' line in the first {HEADER_LIMIT} bytes (header too long or corrupt)"
                )
            raise PlyFormatError(path, "the header has no 'end_header' line (truncated file?)")
        lines.append((number, line))
        pos = end + 1


def _parse_format(path: PathLike, number: int, tokens: list[str]) -> str:
    if len(tokens) != 3 or tokens[1] not in FORMATS:
        raise PlyFormatError(
            path,
            f"header line {number}: bad format line {' '.join(tokens)!r}; expected 'format <{'|'.join(FORMATS)}> 1.0'",
        )
    return tokens[1]


def _parse_element(path: PathLike, number: int, tokens: list[str]) -> tuple[str, int]:
    if len(tokens) != 3 or not re.fullmatch(r"-?[0-9]+", tokens[2]):
        raise PlyFormatError(
            path, f"header line {number}: bad element line {' '.join(tokens)!r}; expected 'element <name> <count>'"
        )
    count = int(tokens[2])
    if count < 0:
        raise PlyFormatError(path, f"header line {number}: element {tokens[1]!r} has a negative count {count}")
    if count > MAX_ELEMENT_COUNT:
        raise PlyFormatError(path, f"header line {number}: element {tokens[1]!r} count {count} is implausibly large")
    return tokens[1], count


def _parse_property(path: PathLike, number: int, tokens: list[str]) -> PlyProperty:
    if len(tokens) == 5 and tokens[1] == "list":
        count_type, item_type, name = tokens[2:]
        for t in (count_type, item_type):
            _check_type(path, number, t)
        if SCALAR_TYPES[count_type][0] == "f":
            raise PlyFormatError(
                path, f"header line {number}: list {name!r} has a non-integer count type {count_type!r}"
            )
        return PlyProperty(name, item_type, count_type)
    if len(tokens) != 3:
        raise PlyFormatError(
            path, f"header line {number}: bad property line {' '.join(tokens)!r}; expected 'property <type> <name>'"
        )
    _check_type(path, number, tokens[1])
    return PlyProperty(tokens[2], tokens[1])


def _check_type(path: PathLike, number: int, ply_type: str) -> None:
    if ply_type not in SCALAR_TYPES:
        raise PlyFormatError(
            path, f"header line {number}: unknown property type {ply_type!r} (known: {', '.join(SCALAR_TYPES)})"
        )


def _type_label(prop: PlyProperty) -> str:
    return prop.type if prop.list_count_type is None else f"list {prop.list_count_type} {prop.type}"
