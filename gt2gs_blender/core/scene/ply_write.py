"""Write Gaussian scenes as INRIA PLY: byte for byte in the source layout when it still fits, else the
canonical INRIA order (float32 core). numpy only, so Blender can export before torch is installed."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..atomic import atomic_write

if TYPE_CHECKING:
    from .gaussians import GaussianScene
from .arrays import SplatArrays
from .codec import as_arrays, require_finite
from .inria import NORMAL_NAMES, REST_PREFIX, core_groups, core_property_names, tensor_view
from .ply import _field_block, _record_dtype
from .ply_header import _PROPERTY_NAME, FORMATS, SCALAR_TYPES, TYPE_FOR_CODE, PathLike, type_code

_ASCII_FORMAT = {"f4": "%.9g", "f8": "%.17g"}  # enough digits to read back exactly; integers use %d


def write_ply(path: PathLike, scene: GaussianScene | SplatArrays, *, fmt: str = "binary_little_endian") -> None:
    """Write a scene (torch ``GaussianScene`` or numpy ``SplatArrays``) atomically; it is not modified. NaN or Inf
    values are refused, as every reader here would refuse the file."""
    if fmt not in FORMATS:
        raise ValueError(f"unknown PLY format {fmt!r}; use one of {', '.join(FORMATS)}")
    require_finite(path, as_arrays(scene), "PLY")
    layout = write_layout(scene)
    records = _records(scene, layout, FORMATS[fmt])
    header = "".join(
        [
            "ply\n",
            f"format {fmt} 1.0\n",
            f"element vertex {len(scene)}\n",
            *(f"property {t} {name}\n" for name, t in layout),
            "end_header\n",
        ]
    ).encode("ascii")
    body = _ascii_body(records, layout) if fmt == "ascii" else records.view(np.uint8)
    atomic_write(Path(path), (header, body))


def write_layout(scene: GaussianScene | SplatArrays) -> tuple[tuple[str, str], ...]:
    """The (property, PLY type) that ``write_ply`` writes: the scene's own layout if it still fits the
    scene, else the canonical INRIA order. ``ValueError`` for extras PLY cannot hold."""
    core = core_property_names(int(scene.sh_rest.shape[1]))
    _check_extras(scene, set(core))
    layout = scene.ply_layout
    if layout is not None and _layout_fits(layout, scene, set(core)):
        return tuple(layout)
    normals = [name for name in NORMAL_NAMES if name in scene.extras]
    order = [*core[:3], *normals, *core[3:]]
    order += [name for name in scene.extras if name not in order]
    return tuple(
        (name, TYPE_FOR_CODE[type_code(scene.extras[name].dtype)] if name in scene.extras else "float")
        for name in order
    )


def _check_extras(scene: GaussianScene | SplatArrays, core: set[str]) -> None:
    for name, values in scene.extras.items():
        if not isinstance(name, str) or not _PROPERTY_NAME.fullmatch(name):
            raise ValueError(f"extra property name {name!r} is not a PLY name (printable ASCII, no spaces)")
        if name in core or name.startswith(REST_PREFIX):
            raise ValueError(f"extra property {name!r} clashes with a Gaussian parameter")
        if not isinstance(values, np.ndarray) or values.shape != (len(scene),):
            raise ValueError(f"extra property {name!r} must be a numpy array of shape ({len(scene)},)")
        if type_code(values.dtype) not in TYPE_FOR_CODE:
            raise ValueError(
                f"extra property {name!r} has dtype {values.dtype}, which PLY cannot store "
                f"(use one of {', '.join(TYPE_FOR_CODE)})"
            )


def _layout_fits(layout: tuple[tuple[str, str], ...], scene: GaussianScene | SplatArrays, core: set[str]) -> bool:
    names = [name for name, _ in layout]
    if len(set(names)) != len(names) or set(names) != core | set(scene.extras):
        return False
    for name, ply_type in layout:
        code = SCALAR_TYPES.get(ply_type)
        wanted = ("f4", "f8") if name in core else (type_code(scene.extras[name].dtype),)
        if code not in wanted:
            return False
    return True


def _records(scene: GaussianScene | SplatArrays, layout: tuple[tuple[str, str], ...], byte_order: str) -> np.ndarray:
    """The vertex records of ``scene`` as a structured array in ``layout``."""
    records = np.empty(len(scene), _record_dtype(layout, byte_order))
    with np.errstate(over="ignore"):
        for key, names in core_groups(int(scene.sh_rest.shape[1])).items():
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
        np.copyto(tensor_view(key, block), values)
        return
    storage = np.empty((len(records), len(names)), values.dtype)
    np.copyto(tensor_view(key, storage), values)
    for i, name in enumerate(names):
        records[name] = storage[:, i]


def _ascii_body(records: np.ndarray, layout: tuple[tuple[str, str], ...]) -> bytes:
    row = " ".join(_ASCII_FORMAT.get(SCALAR_TYPES[t], "%d") for _, t in layout)
    lines = [row % values for values in records.tolist()]
    return ("\n".join(lines) + "\n" if lines else "").encode("ascii")
