"""Read and write 3D Gaussian Splatting scenes in the INRIA PLY format.

Supported: ``binary_little_endian``, ``binary_big_endian`` and ``ascii``; SH degree 0-3 (``f_rest_*``
stored channel-major, R's coefficients first); optional normals; any extra scalar vertex property,
kept in ``GaussianScene.extras`` (native byte order, the file's type) so it survives a round trip.

Choices:
- ``scene.ply_layout`` records the vertex properties (name, type as spelled) in file order. Writing
  a scene that still fits its layout reproduces a vertex-only INRIA file byte for byte (header
  ``comment``/``obj_info`` lines and other elements are not written back). A scene that no longer
  fits (other SH degree, changed extras) is written in the canonical INRIA order, float32 core.
- Elements other than ``vertex`` are parsed (list properties included) and skipped; binary elements
  with list properties before ``vertex`` are walked row by row (rare, slower). Bytes after the vertex
  data are ignored (later elements, padding). ``vertex`` itself must have scalar properties only.
- ASCII data is one element row per line (LF or CRLF), as every PLY writer emits it.
- Only the Gaussian parameters are checked for NaN/Inf; extras are opaque and kept as they are.
- Every problem with the file raises ``PlyFormatError`` naming the file; a scene that cannot be
  written (bad extras, unknown format) is a caller bug and raises ``ValueError``.
- This module needs numpy only: ``read_ply_arrays`` returns ``SplatArrays`` (the numpy twin of
  ``GaussianScene``) and ``write_ply`` takes either, so Blender can import and export splats before
  the engine's torch dependency is installed. ``read_ply`` returns torch tensors.
"""
from __future__ import annotations

import io
import os
import re
import struct
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, BinaryIO, Iterable

import numpy as np
from .atomic import atomic_write
from .errors import PlyFormatError

if TYPE_CHECKING:
    from .scene import GaussianScene

PathLike = str | os.PathLike

HEADER_LIMIT = 64 * 1024
"""Largest header accepted; anything longer is not a real PLY header."""

MAX_ELEMENT_COUNT = 2**32 - 1

FORMATS = {"binary_little_endian": "<", "binary_big_endian": ">", "ascii": "="}

SCALAR_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}
"""PLY scalar type names (classic and sized aliases) -> numpy type codes."""

_TYPE_FOR_CODE = {"i1": "char", "u1": "uchar", "i2": "short", "u2": "ushort",
                  "i4": "int", "u4": "uint", "f4": "float", "f8": "double"}
_STRUCT_CHAR = {"i1": "b", "u1": "B", "i2": "h", "u2": "H", "i4": "i", "u4": "I"}
_ASCII_FORMAT = {"f4": "%.9g", "f8": "%.17g"}  # enough digits to read back exactly; integers use %d
_PROPERTY_NAME = re.compile(r"[!-~]+")
_REQUIRED = ("x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity",
             "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3")


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


# -- reading ------------------------------------------------------------------------------------------


def read_ply_header(path: PathLike) -> PlyHeader:
    """Parse and check the header only (fast, reads at most 64 KiB)."""
    with _open(path) as f:
        return _parse_header(path, _read(path, f, HEADER_LIMIT))


@dataclass
class SplatArrays:
    """The numpy twin of ``GaussianScene``: the same field names, shapes and meaning, float32 arrays."""

    means: np.ndarray
    quats: np.ndarray
    log_scales: np.ndarray
    opacity_logits: np.ndarray
    sh_dc: np.ndarray
    sh_rest: np.ndarray
    extras: dict[str, np.ndarray]
    ply_layout: tuple[tuple[str, str], ...] | None = None

    def __len__(self) -> int:
        return int(self.means.shape[0])

    def tensors(self) -> dict[str, np.ndarray]:
        """The parameter arrays by name (the keys of ``GaussianScene.tensors()``)."""
        return {"means": self.means, "quats": self.quats, "log_scales": self.log_scales,
                "opacity_logits": self.opacity_logits, "sh_dc": self.sh_dc, "sh_rest": self.sh_rest}


def read_ply(path: PathLike, *, drop_invalid: bool = False) -> GaussianScene:
    """Load a 3DGS PLY as a ``GaussianScene`` of float32 tensors (see ``read_ply_arrays``)."""
    import torch

    from .scene import GaussianScene

    arrays = read_ply_arrays(path, drop_invalid=drop_invalid)
    return GaussianScene(**{key: torch.from_numpy(values) for key, values in arrays.tensors().items()},
                         extras=arrays.extras, ply_layout=arrays.ply_layout)


def read_ply_arrays(path: PathLike, *, drop_invalid: bool = False) -> SplatArrays:
    """Load a 3DGS PLY as numpy arrays.

    Gaussians with NaN/Inf parameters make the file an error unless ``drop_invalid``, which drops
    them with a warning.
    """
    with _open(path) as f:
        header = _parse_header(path, _read(path, f, HEADER_LIMIT))
        k = _check_gaussian_layout(path, header)
        f.seek(header.header_size)
        if header.format == "ascii":
            records = _ascii_vertices(path, _read(path, f, -1), header)
        else:
            records = _binary_vertices(path, f, header)
    return _arrays_from_records(path, header, records, k, drop_invalid)


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
                    path, f"header line {number}: duplicate property {prop.name!r} in element {element_name!r}")
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
                raise PlyFormatError(path, f"no 'end_header' line in the first {HEADER_LIMIT} bytes "
                                           "(header too long or corrupt)")
            raise PlyFormatError(path, "the header has no 'end_header' line (truncated file?)")
        lines.append((number, line))
        pos = end + 1


def _parse_format(path: PathLike, number: int, tokens: list[str]) -> str:
    if len(tokens) != 3 or tokens[1] not in FORMATS:
        raise PlyFormatError(
            path, f"header line {number}: bad format line {' '.join(tokens)!r}; expected "
                  f"'format <{'|'.join(FORMATS)}> 1.0'")
    return tokens[1]


def _parse_element(path: PathLike, number: int, tokens: list[str]) -> tuple[str, int]:
    if len(tokens) != 3 or not re.fullmatch(r"-?[0-9]+", tokens[2]):
        raise PlyFormatError(path, f"header line {number}: bad element line {' '.join(tokens)!r}; "
                                   "expected 'element <name> <count>'")
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
                path, f"header line {number}: list {name!r} has a non-integer count type {count_type!r}")
        return PlyProperty(name, item_type, count_type)
    if len(tokens) != 3:
        raise PlyFormatError(path, f"header line {number}: bad property line {' '.join(tokens)!r}; "
                                   "expected 'property <type> <name>'")
    _check_type(path, number, tokens[1])
    return PlyProperty(tokens[2], tokens[1])


def _check_type(path: PathLike, number: int, ply_type: str) -> None:
    if ply_type not in SCALAR_TYPES:
        raise PlyFormatError(path, f"header line {number}: unknown property type {ply_type!r} "
                                   f"(known: {', '.join(SCALAR_TYPES)})")


def _type_label(prop: PlyProperty) -> str:
    return prop.type if prop.list_count_type is None else f"list {prop.list_count_type} {prop.type}"


def _check_gaussian_layout(path: PathLike, header: PlyHeader) -> int:
    """Check that the vertex properties form a 3DGS layout; return K, the f_rest count per channel."""
    props = header.vertex.properties
    lists = [p.name for p in props if p.list_count_type is not None]
    if lists:
        raise PlyFormatError(path, f"vertex list properties are not supported ({', '.join(lists)}); "
                                   "3DGS vertices have scalar properties only")
    types = {p.name: p.type for p in props}
    missing = [name for name in _REQUIRED if name not in types]
    if missing:
        raise PlyFormatError(path, f"missing required properties {', '.join(missing)} "
                                   "(not a 3D Gaussian Splatting PLY?)")
    rest = [p.name for p in props if p.name.startswith("f_rest_")]
    k = len(rest) // 3
    if len(rest) not in (3 * ((d + 1) ** 2 - 1) for d in range(4)) or \
            set(rest) != {f"f_rest_{i}" for i in range(len(rest))}:
        raise PlyFormatError(path, f"{len(rest)} f_rest properties do not form an SH degree 0-3 layout "
                                   "(expected f_rest_0 .. f_rest_<n-1> with n = 0, 9, 24 or 45)")
    not_float = [f"{name} ({types[name]})" for name in (*_REQUIRED, *rest) if SCALAR_TYPES[types[name]][0] != "f"]
    if not_float:
        raise PlyFormatError(path, f"Gaussian properties must be float or double: {', '.join(not_float)}")
    return k


def _record_dtype(properties: Iterable[tuple[str, str]], byte_order: str) -> np.dtype:
    return np.dtype([(name, byte_order + SCALAR_TYPES[t]) for name, t in properties])


def _binary_vertices(path: PathLike, f: BinaryIO, header: PlyHeader) -> np.ndarray:
    """The vertex records as a structured array in the file's byte order."""
    byte_order = FORMATS[header.format]
    offset = header.header_size + _bytes_before_vertex(path, f, header, byte_order)
    dtype = _record_dtype(header.properties, byte_order)
    need = header.vertex_count * dtype.itemsize
    available = os.fstat(f.fileno()).st_size - offset
    if need > available:
        raise PlyFormatError(
            path, f"truncated: the header promises {header.vertex_count} vertices ({need} bytes) but only "
                  f"{max(available, 0)} bytes of vertex data follow (truncated file or wrong vertex count)")
    buffer = np.empty(need, np.uint8)
    f.seek(offset)
    try:
        got = f.readinto(buffer)
    except OSError as exc:
        raise PlyFormatError(path, f"cannot be read ({exc.strerror or exc})") from None
    if got != need:
        raise PlyFormatError(path, f"truncated: read {got} of {need} bytes of vertex data")
    return buffer.view(dtype)


def _bytes_before_vertex(path: PathLike, f: BinaryIO, header: PlyHeader, byte_order: str) -> int:
    """Size of the binary data of the elements that precede 'vertex'."""
    size = 0
    for element in header.elements[:header.elements.index(header.vertex)]:
        if any(p.list_count_type for p in element.properties):
            f.seek(header.header_size + size)
            size += _walk_list_element(path, _read(path, f, -1), element, byte_order)
        else:
            size += element.count * _record_dtype(((p.name, p.type) for p in element.properties), "<").itemsize
    return size


def _walk_list_element(path: PathLike, data: bytes, element: PlyElement, byte_order: str) -> int:
    """Byte size of an element with list properties at the start of ``data`` (row by row).

    Every row reads at least one list count byte or stops with an error, so a corrupt row count
    (up to 2^32 - 1) costs at most one step per byte of the file, never a hang.
    """
    pos = 0
    for _ in range(element.count):
        for prop in element.properties:
            item = np.dtype(SCALAR_TYPES[prop.type]).itemsize
            if prop.list_count_type is None:
                pos += item
                continue
            code = SCALAR_TYPES[prop.list_count_type]
            count_size = np.dtype(code).itemsize
            if pos + count_size > len(data):
                raise PlyFormatError(path, f"truncated: the data of element {element.name!r} ends early")
            (length,) = struct.unpack_from(byte_order + _STRUCT_CHAR[code], data, pos)
            if length < 0:
                raise PlyFormatError(path, f"element {element.name!r}: negative list length {length}")
            pos += count_size + length * item
        if pos > len(data):
            raise PlyFormatError(path, f"truncated: the data of element {element.name!r} ends early")
    return pos


def _ascii_vertices(path: PathLike, body: bytes, header: PlyHeader) -> np.ndarray:
    """The vertex rows of an ASCII body as a structured array (native byte order)."""
    first = sum(e.count for e in header.elements[:header.elements.index(header.vertex)])
    count = header.vertex_count
    newlines = np.flatnonzero(np.frombuffer(body, np.uint8) == ord("\n"))
    n_lines = len(newlines) + (1 if body and not body.endswith(b"\n") else 0)
    if first + count > n_lines:
        raise PlyFormatError(
            path, f"truncated: the ASCII data has {n_lines} lines but the header needs {first + count} "
                  f"({first} for earlier elements, {count} vertex rows)")
    dtype = _record_dtype(header.properties, "=")
    if count == 0:
        return np.empty(0, dtype)
    begin = 0 if first == 0 else int(newlines[first - 1]) + 1
    last = first + count - 1
    end = int(newlines[last]) if last < len(newlines) else len(body)
    values = _parse_ascii_table(path, body[begin:end], len(dtype.names))
    if values.shape[0] != count:
        raise PlyFormatError(path, f"the ASCII vertex data has {values.shape[0]} rows, the header says {count} "
                                   "(blank lines in the data?)")
    records = np.empty(count, dtype)
    with np.errstate(over="ignore"):  # values beyond float32 become Inf, reported by the caller
        for column, (name, ply_type) in zip(values.T, header.properties):
            records[name] = _ascii_column(path, name, ply_type, column)
    return records


def _parse_ascii_table(path: PathLike, text: bytes, n_columns: int) -> np.ndarray:
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            values = np.loadtxt(io.StringIO(text.decode("ascii")), dtype=np.float64, comments=None, ndmin=2)
    except UnicodeDecodeError:
        raise PlyFormatError(path, "the ASCII vertex data contains non-ASCII bytes") from None
    except ValueError as exc:
        reason = str(exc).split(";")[0]
        raise PlyFormatError(path, f"malformed ASCII vertex data ({reason})") from None
    if values.shape[1] != n_columns and values.size:
        raise PlyFormatError(path, f"the ASCII vertex rows have {values.shape[1]} values, "
                                   f"the header declares {n_columns} properties")
    return values


def _ascii_column(path: PathLike, name: str, ply_type: str, column: np.ndarray) -> np.ndarray:
    """Check that integer properties hold in-range integers; floats pass through."""
    code = SCALAR_TYPES[ply_type]
    if code[0] == "f":
        return column
    info = np.iinfo(code)
    bad = int(np.count_nonzero(~((column == np.floor(column)) & (column >= info.min) & (column <= info.max))))
    if bad:
        raise PlyFormatError(path, f"ASCII property {name!r} ({ply_type}) has {bad} values that are not "
                                   f"integers in [{info.min}, {info.max}]")
    return column


def _core_groups(k: int) -> dict[str, list[str]]:
    """Scene tensor -> its PLY properties in canonical INRIA order (f_rest channel-major)."""
    return {
        "means": ["x", "y", "z"],
        "sh_dc": [f"f_dc_{i}" for i in range(3)],
        "sh_rest": [f"f_rest_{i}" for i in range(3 * k)],
        "opacity_logits": ["opacity"],
        "log_scales": [f"scale_{i}" for i in range(3)],
        "quats": [f"rot_{i}" for i in range(4)],
    }


def _tensor_view(key: str, storage: np.ndarray) -> np.ndarray:
    """View (N, columns) in PLY order with the shape of scene tensor ``key``: sh_rest (N,3K) -> (N,K,3)."""
    n = storage.shape[0]
    if key == "sh_rest":
        return storage.reshape(n, 3, storage.shape[1] // 3).transpose(0, 2, 1)
    if key == "opacity_logits":
        return storage.reshape(n)
    return storage


def _field_block(records: np.ndarray, names: list[str]) -> np.ndarray | None:
    """An (N, len(names)) view of the fields when they are consecutive and of one type (the usual case)."""
    if not names or not len(records):
        return None
    fields = records.dtype.fields
    dtype, start = fields[names[0]][:2]
    if any(fields[name][:2] != (dtype, start + i * dtype.itemsize) for i, name in enumerate(names)):
        return None
    return np.ndarray((len(records), len(names)), dtype, records.view(np.uint8), start,
                      (records.itemsize, dtype.itemsize))


def _read_group(records: np.ndarray, key: str, names: list[str]) -> np.ndarray:
    """Scene tensor ``key`` as contiguous float32, in one pass over the records when possible."""
    storage = _field_block(records, names)
    if storage is None:
        storage = np.empty((len(records), len(names)), np.float32)
        for i, name in enumerate(names):
            storage[:, i] = records[name]
    view = _tensor_view(key, storage)
    out = np.empty(view.shape, np.float32)
    np.copyto(out, view)
    return out


def _arrays_from_records(
    path: PathLike, header: PlyHeader, records: np.ndarray, k: int, drop_invalid: bool,
) -> SplatArrays:
    groups = _core_groups(k)
    with np.errstate(over="ignore"):  # double values beyond float32 become Inf, reported below
        arrays = {key: _read_group(records, key, names) for key, names in groups.items()}
    core = {name for names in groups.values() for name in names}
    extras = {name: records[name].astype(records.dtype[name].newbyteorder("="))
              for name, _ in header.properties if name not in core}
    finite = np.ones(len(records), bool)
    for values in arrays.values():
        if not np.isfinite(values).all():  # per-row check only when needed: it is 10x slower
            finite &= np.isfinite(values).reshape(len(records), -1).all(axis=1)
    n_bad = len(records) - int(finite.sum())
    if n_bad:
        if not drop_invalid:
            raise PlyFormatError(
                path, f"{n_bad} of {len(records)} Gaussians have non-finite values (NaN or Inf) in their "
                      "parameters; use --drop-invalid (drop_invalid=True) to load the file without them")
        warnings.warn(f"{os.fspath(path)}: dropped {n_bad} of {len(records)} Gaussians with non-finite values",
                      stacklevel=4)
        arrays = {key: values[finite] for key, values in arrays.items()}
        extras = {name: values[finite] for name, values in extras.items()}
    return SplatArrays(**arrays, extras=extras, ply_layout=header.properties)


# -- writing ------------------------------------------------------------------------------------------


def write_ply(path: PathLike, scene: GaussianScene | SplatArrays, *, fmt: str = "binary_little_endian") -> None:
    """Write a scene (torch ``GaussianScene`` or numpy ``SplatArrays``) atomically; it is not modified."""
    if fmt not in FORMATS:
        raise ValueError(f"unknown PLY format {fmt!r}; use one of {', '.join(FORMATS)}")
    layout = _write_layout(scene)
    records = _records(scene, layout, FORMATS[fmt])
    header = "".join(
        ["ply\n", f"format {fmt} 1.0\n", f"element vertex {len(scene)}\n",
         *(f"property {t} {name}\n" for name, t in layout), "end_header\n"]
    ).encode("ascii")
    body = _ascii_body(records, layout) if fmt == "ascii" else records.view(np.uint8)
    atomic_write(Path(path), (header, body))


def _write_layout(scene: GaussianScene | SplatArrays) -> tuple[tuple[str, str], ...]:
    """The scene's own layout if it still fits the scene, else the canonical INRIA order."""
    core = [name for names in _core_groups(int(scene.sh_rest.shape[1])).values() for name in names]
    _check_extras(scene, set(core))
    layout = scene.ply_layout
    if layout is not None and _layout_fits(layout, scene, set(core)):
        return tuple(layout)
    normals = [name for name in ("nx", "ny", "nz") if name in scene.extras]
    order = [*core[:3], *normals, *core[3:]]
    order += [name for name in scene.extras if name not in order]
    return tuple((name, _TYPE_FOR_CODE[_code(scene.extras[name].dtype)] if name in scene.extras else "float")
                 for name in order)


def _code(dtype: np.dtype) -> str:
    return f"{dtype.kind}{dtype.itemsize}"


def _check_extras(scene: GaussianScene | SplatArrays, core: set[str]) -> None:
    for name, values in scene.extras.items():
        if not isinstance(name, str) or not _PROPERTY_NAME.fullmatch(name):
            raise ValueError(f"extra property name {name!r} is not a PLY name (printable ASCII, no spaces)")
        if name in core or name.startswith("f_rest_"):
            raise ValueError(f"extra property {name!r} clashes with a Gaussian parameter")
        if not isinstance(values, np.ndarray) or values.shape != (len(scene),):
            raise ValueError(f"extra property {name!r} must be a numpy array of shape ({len(scene)},)")
        if _code(values.dtype) not in _TYPE_FOR_CODE:
            raise ValueError(f"extra property {name!r} has dtype {values.dtype}, which PLY cannot store "
                             f"(use one of {', '.join(_TYPE_FOR_CODE)})")


def _layout_fits(layout: tuple[tuple[str, str], ...], scene: GaussianScene | SplatArrays, core: set[str]) -> bool:
    names = [name for name, _ in layout]
    if len(set(names)) != len(names) or set(names) != core | set(scene.extras):
        return False
    for name, ply_type in layout:
        code = SCALAR_TYPES.get(ply_type)
        wanted = ("f4", "f8") if name in core else (_code(scene.extras[name].dtype),)
        if code not in wanted:
            return False
    return True


def _records(scene: GaussianScene | SplatArrays, layout: tuple[tuple[str, str], ...], byte_order: str) -> np.ndarray:
    """The vertex records of ``scene`` as a structured array in ``layout``."""
    records = np.empty(len(scene), _record_dtype(layout, byte_order))
    with np.errstate(over="ignore"):
        for key, names in _core_groups(int(scene.sh_rest.shape[1])).items():
            _write_group(records, key, names, _float_array(scene.tensors()[key]))
        for name in scene.extras:
            records[name] = scene.extras[name]
    return records


def _float_array(values) -> np.ndarray:
    """A torch tensor or numpy array as a float32 (or float64) numpy array."""
    if hasattr(values, "detach"):
        values = values.detach().cpu().numpy()
    return values if values.dtype in (np.float32, np.float64) else values.astype(np.float32)


def _write_group(records: np.ndarray, key: str, names: list[str], values: np.ndarray) -> None:
    """Store scene tensor ``values`` into its fields, in one pass when they are consecutive."""
    block = _field_block(records, names)
    if block is not None:
        np.copyto(_tensor_view(key, block), values)
        return
    storage = np.empty((len(records), len(names)), values.dtype)
    np.copyto(_tensor_view(key, storage), values)
    for i, name in enumerate(names):
        records[name] = storage[:, i]


def _ascii_body(records: np.ndarray, layout: tuple[tuple[str, str], ...]) -> bytes:
    row = " ".join(_ASCII_FORMAT.get(SCALAR_TYPES[t], "%d") for _, t in layout)
    lines = [row % values for values in records.tolist()]
    return ("\n".join(lines) + "\n" if lines else "").encode("ascii")
