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
    DROP_HINT,
    PathLike,
    as_arrays,
    canonical_quats,
    colour_from_dc,
    dc_from_colour,
    dropped_notes,
    logit,
    make_arrays,
    read_bytes,
    require_finite,
    sigmoid,
)

RECORD = np.dtype([("position", "<f4", 3), ("scale", "<f4", 3), ("rgba", "u1", 4), ("rotation", "u1", 4)])
"""One splat's 32 bytes."""
LOG_SCALE_RANGE = (float(np.log(np.finfo(np.float32).tiny)), float(np.log(np.finfo(np.float32).max)) - 1e-4)
"""Log scales whose exp is a normal, finite float32 (-87.3..88.7): the writer clamps to these, as a zero or
infinite scale would make a file that no reader accepts."""


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
    _refuse_flat(path, records["scale"], drop_invalid)
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


def _refuse_flat(path: PathLike, scales: np.ndarray, drop_invalid: bool) -> None:
    """A zero or negative linear scale has no log scale: an error naming the file (``drop_invalid`` drops them)."""
    flat = int(np.count_nonzero((scales <= 0.0).any(axis=1)))
    if flat and not drop_invalid:
        raise SplatFormatError(path, f"{flat} of {len(scales)} splats have a zero or negative scale; {DROP_HINT}")


def write_splat(path: PathLike, scene: object) -> list[str]:
    """Write a scene as ``.splat`` (atomically); one-line notes on what the format could not keep, and on log
    scales clamped to what float32 holds (see ``LOG_SCALE_RANGE``)."""
    arrays = as_arrays(scene)
    require_finite(path, arrays, "splat")
    records = np.zeros(len(arrays), RECORD)
    records["position"] = arrays.means
    log_scales = np.clip(arrays.log_scales.astype(np.float64), *LOG_SCALE_RANGE)
    records["scale"] = np.exp(log_scales)
    colour = np.concatenate([colour_from_dc(arrays.sh_dc), sigmoid(arrays.opacity_logits)[:, None]], axis=1)
    records["rgba"] = _to_u8(colour)
    records["rotation"] = _to_u8((canonical_quats(arrays.quats) + 1.0) / 2.0)
    atomic_write(path, records.tobytes())
    notes = dropped_notes(arrays, "splat", keeps_sh_degree=0)
    clamped = int(np.count_nonzero(log_scales != arrays.log_scales))
    if clamped:
        low, high = LOG_SCALE_RANGE
        notes.append(f"splat clamps log scales to {low:.1f}..{high:.1f} (float32 scales): {clamped} values clamped")
    return notes


def _to_u8(unit: np.ndarray) -> np.ndarray:
    """Values in 0..1 (clipped) to the nearest of 256 levels."""
    return np.round(np.clip(unit, 0.0, 1.0) * 255.0).astype(np.uint8)
