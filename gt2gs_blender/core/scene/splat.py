"""The antimatter15 ``.splat`` format: a headerless array of 32-byte records, one per splat. numpy only.

Each record, little-endian: position (3 x float32), linear scale (3 x float32), colour and opacity
(4 x uint8: 0.5 + SH_C0 * f_dc and sigmoid(opacity), times 255), rotation (4 x uint8, w x y z, the
unit quaternion mapped from -1..1 to 0..255). The format keeps positions and scales exactly (float32),
colour, opacity and rotation to 8 bits, and no view-dependent colour (SH bands above 0) or extras.
"""

from __future__ import annotations

import numpy as np

from ..atomic import atomic_write
from ..errors import SplatFormatError
from .arrays import SplatArrays
from .codec import (
    PathLike,
    as_arrays,
    canonical_quats,
    colour_from_dc,
    dc_from_colour,
    dropped_notes,
    logit,
    make_arrays,
    read_bytes,
    sigmoid,
)

RECORD = np.dtype([("position", "<f4", 3), ("scale", "<f4", 3), ("rgba", "u1", 4), ("rotation", "u1", 4)])
"""One splat's 32 bytes."""


def read_splat(path: PathLike, *, drop_invalid: bool = False) -> SplatArrays:
    """Load a ``.splat`` file (SH degree 0: the format has no higher bands)."""
    data = read_bytes(path)
    if len(data) % RECORD.itemsize:
        raise SplatFormatError(
            path,
            f"{len(data):,} bytes is not a whole number of {RECORD.itemsize}-byte splat records (truncated, or "
            "not a .splat file)",
        )
    records = np.frombuffer(data, RECORD)
    with np.errstate(divide="ignore", invalid="ignore"):
        log_scales = np.log(records["scale"].astype(np.float64))
    rotation = records["rotation"].astype(np.float64) / 255.0 * 2.0 - 1.0
    return make_arrays(
        path,
        means=records["position"],
        quats=canonical_quats(rotation),
        log_scales=log_scales,
        opacity_logits=logit(records["rgba"][:, 3] / 255.0),
        sh_dc=dc_from_colour(records["rgba"][:, :3] / 255.0),
        sh_rest=np.zeros((len(records), 0, 3), np.float32),
        drop_invalid=drop_invalid,
    )


def write_splat(path: PathLike, scene: object) -> list[str]:
    """Write a scene as ``.splat`` (atomically); one-line notes on what the format could not keep."""
    arrays = as_arrays(scene)
    records = np.zeros(len(arrays), RECORD)
    records["position"] = arrays.means
    records["scale"] = np.exp(arrays.log_scales.astype(np.float64))
    colour = np.concatenate([colour_from_dc(arrays.sh_dc), sigmoid(arrays.opacity_logits)[:, None]], axis=1)
    records["rgba"] = _to_u8(colour)
    records["rotation"] = _to_u8((canonical_quats(arrays.quats) + 1.0) / 2.0)
    atomic_write(path, records.tobytes())
    return dropped_notes(arrays, "splat", keeps_sh_degree=0)


def _to_u8(unit: np.ndarray) -> np.ndarray:
    """Values in 0..1 (clipped) to the nearest of 256 levels."""
    return np.round(np.clip(unit, 0.0, 1.0) * 255.0).astype(np.uint8)
