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
import struct
import warnings
from collections.abc import Iterable
from typing import TYPE_CHECKING, BinaryIO

import numpy as np

from ..errors import NotGaussianPlyError, PlyFormatError

if TYPE_CHECKING:
    from .gaussians import GaussianScene
from .arrays import SplatArrays
from .inria import REQUIRED, REST_PREFIX, core_groups, rest_per_channel, tensor_view
from .ply_header import (
    FORMATS,
    HEADER_LIMIT,
    SCALAR_TYPES,
    PathLike,
    PlyElement,
    PlyHeader,
    _open,
    _parse_header,
    _read,
)

_STRUCT_CHAR = {"i1": "b", "u1": "B", "i2": "h", "u2": "H", "i4": "i", "u4": "I"}


def read_ply(path: PathLike, *, drop_invalid: bool = False) -> GaussianScene:
    """Load a 3DGS PLY as a ``GaussianScene`` of float32 tensors (see ``read_ply_arrays``)."""
    from .gaussians import GaussianScene

    return GaussianScene.from_arrays(read_ply_arrays(path, drop_invalid=drop_invalid))


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


def _check_gaussian_layout(path: PathLike, header: PlyHeader) -> int:
    """Check that the vertex properties form a 3DGS layout; return K, the f_rest count per channel."""
    props = header.vertex.properties
    lists = [p.name for p in props if p.list_count_type is not None]
    if lists:
        raise PlyFormatError(
            path,
            f"vertex list properties are not supported ({', '.join(lists)}); 3DGS vertices have scalar properties only",
        )
    types = {p.name: p.type for p in props}
    missing = [name for name in REQUIRED if name not in types]
    if missing:
        raise NotGaussianPlyError(
            path,
            f"missing required properties {', '.join(missing)}: a mesh or plain point cloud, not a 3D Gaussian "
            "Splatting PLY",
        )
    rest = [p.name for p in props if p.name.startswith(REST_PREFIX)]
    k = rest_per_channel(rest)
    if k is None:
        raise PlyFormatError(
            path,
            f"{len(rest)} f_rest properties do not form an SH degree 0-3 layout "
            "(expected f_rest_0 .. f_rest_<n-1> with n = 0, 9, 24 or 45)",
        )
    not_float = [f"{name} ({types[name]})" for name in (*REQUIRED, *rest) if SCALAR_TYPES[types[name]][0] != "f"]
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
            path,
            f"truncated: the header promises {header.vertex_count} vertices ({need} bytes) but only "
            f"{max(available, 0)} bytes of vertex data follow (truncated file or wrong vertex count)",
        )
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
    for element in header.elements[: header.elements.index(header.vertex)]:
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
    first = sum(e.count for e in header.elements[: header.elements.index(header.vertex)])
    count = header.vertex_count
    newlines = np.flatnonzero(np.frombuffer(body, np.uint8) == ord("\n"))
    n_lines = len(newlines) + (1 if body and not body.endswith(b"\n") else 0)
    if first + count > n_lines:
        raise PlyFormatError(
            path,
            f"truncated: the ASCII data has {n_lines} lines but the header needs {first + count} "
            f"({first} for earlier elements, {count} vertex rows)",
        )
    dtype = _record_dtype(header.properties, "=")
    if count == 0:
        return np.empty(0, dtype)
    begin = 0 if first == 0 else int(newlines[first - 1]) + 1
    last = first + count - 1
    end = int(newlines[last]) if last < len(newlines) else len(body)
    values = _parse_ascii_table(path, body[begin:end], len(dtype.names))
    if values.shape[0] != count:
        raise PlyFormatError(
            path,
            f"the ASCII vertex data has {values.shape[0]} rows, the header says {count} (blank lines in the data?)",
        )
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
        raise PlyFormatError(
            path, f"the ASCII vertex rows have {values.shape[1]} values, the header declares {n_columns} properties"
        )
    return values


def _ascii_column(path: PathLike, name: str, ply_type: str, column: np.ndarray) -> np.ndarray:
    """Check that integer properties hold in-range integers; floats pass through."""
    code = SCALAR_TYPES[ply_type]
    if code[0] == "f":
        return column
    info = np.iinfo(code)
    bad = int(np.count_nonzero(~((column == np.floor(column)) & (column >= info.min) & (column <= info.max))))
    if bad:
        raise PlyFormatError(
            path,
            f"ASCII property {name!r} ({ply_type}) has {bad} values that are not integers in [{info.min}, {info.max}]",
        )
    return column


def _field_block(records: np.ndarray, names: list[str]) -> np.ndarray | None:
    """An (N, len(names)) view of the fields when they are consecutive and of one type (the usual case)."""
    if not names or not len(records):
        return None
    fields = records.dtype.fields
    dtype, start = fields[names[0]][:2]
    if any(fields[name][:2] != (dtype, start + i * dtype.itemsize) for i, name in enumerate(names)):
        return None
    return np.ndarray(
        (len(records), len(names)), dtype, records.view(np.uint8), start, (records.itemsize, dtype.itemsize)
    )


def _read_group(records: np.ndarray, key: str, names: list[str]) -> np.ndarray:
    """Scene tensor ``key`` as contiguous float32, in one pass over the records when possible."""
    storage = _field_block(records, names)
    if storage is None:
        storage = np.empty((len(records), len(names)), np.float32)
        for i, name in enumerate(names):
            storage[:, i] = records[name]
    view = tensor_view(key, storage)
    out = np.empty(view.shape, np.float32)
    np.copyto(out, view)
    return out


def _arrays_from_records(
    path: PathLike,
    header: PlyHeader,
    records: np.ndarray,
    k: int,
    drop_invalid: bool,
) -> SplatArrays:
    groups = core_groups(k)
    with np.errstate(over="ignore"):  # double values beyond float32 become Inf, reported below
        arrays = {key: _read_group(records, key, names) for key, names in groups.items()}
    core = {name for names in groups.values() for name in names}
    extras = {
        name: records[name].astype(records.dtype[name].newbyteorder("="))
        for name, _ in header.properties
        if name not in core
    }
    finite = np.ones(len(records), bool)
    for values in arrays.values():
        if not np.isfinite(values).all():  # per-row check only when needed: it is 10x slower
            finite &= np.isfinite(values).reshape(len(records), -1).all(axis=1)
    n_bad = len(records) - int(finite.sum())
    if n_bad:
        if not drop_invalid:
            raise PlyFormatError(
                path,
                f"{n_bad} of {len(records)} Gaussians have non-finite values (NaN or Inf) in their "
                "parameters; use --drop-invalid (drop_invalid=True) to load the file without them",
            )
        warnings.warn(
            f"{os.fspath(path)}: dropped {n_bad} of {len(records)} Gaussians with non-finite values", stacklevel=4
        )
        arrays = {key: values[finite] for key, values in arrays.items()}
        extras = {name: values[finite] for name, values in extras.items()}
    return SplatArrays(**arrays, extras=extras, ply_layout=header.properties)
