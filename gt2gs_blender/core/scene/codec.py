"""What every splat file format's reader and writer shares: activations, colours, quaternions, the checked
``SplatArrays`` a reader returns, capped decompression and atomic output. numpy only.

Quantised formats store activated values (linear or log scale, opacity in 0..1, colour in 0..1); the
engine keeps 3DGS's raw parameters (log scales, opacity logits, SH coefficients). The conversions
here are the one place where the two meet, written to be stable at the ends of their ranges.
"""

from __future__ import annotations

import gzip
import io
import os
import warnings
import zlib
from typing import TYPE_CHECKING

import numpy as np

from ..errors import SplatFormatError
from .arrays import SplatArrays
from .inria import SH_C0, sh_degree_from_rest

if TYPE_CHECKING:
    from .gaussians import GaussianScene

PathLike = str | os.PathLike

MAX_DECOMPRESSED = 8 * 2**30
"""Largest decompressed payload a reader accepts (about 60M splats of SH degree 3): beyond it a file is a
decompression bomb, not a scene."""
EXPANSION = 16
"""How many times its own size a compressed file may declare when decoded: real SPZ and SOG files expand
1.4-2x (deflate's most is 1032x, for runs of one byte)."""
DECODE_FLOOR = 64 * 2**20
"""Any file may declare this much decoded data, however small it is (a scene of identical splats packs tight)."""
DROP_HINT = "use --drop-invalid (drop_invalid=True) to load the file without them"
FLOAT32_MAX = float(np.finfo(np.float32).max)
OPACITY_EPS = 1e-6
"""Opacities are clipped to [eps, 1 - eps] before the logit, so 0 and 1 in a file stay finite."""


def sigmoid(x: np.ndarray) -> np.ndarray:
    """The logistic function, without overflow for large |x|."""
    x = np.asarray(x, np.float64)
    return np.exp(-np.logaddexp(0.0, -x))


def logit(p: np.ndarray, eps: float = OPACITY_EPS) -> np.ndarray:
    """The inverse of :func:`sigmoid`, with p clipped to [eps, 1 - eps] so it is always finite."""
    p = np.clip(np.asarray(p, np.float64), eps, 1.0 - eps)
    return np.log(p) - np.log1p(-p)


def colour_from_dc(sh_dc: np.ndarray) -> np.ndarray:
    """Base colour (0..1 in a well-formed scene, not clipped) of DC SH coefficients."""
    return 0.5 + SH_C0 * np.asarray(sh_dc, np.float64)


def dc_from_colour(colour: np.ndarray) -> np.ndarray:
    """DC SH coefficients of a base colour (the inverse of :func:`colour_from_dc`)."""
    return (np.asarray(colour, np.float64) - 0.5) / SH_C0


def canonical_quats(quats: np.ndarray) -> np.ndarray:
    """Unit quaternions (w, x, y, z) with w >= 0 (q and -q are one rotation); a zero quaternion becomes
    the identity."""
    q = np.asarray(quats, np.float64)
    norm = np.linalg.norm(q, axis=-1, keepdims=True)
    unit = np.where(norm > 0.0, q / np.where(norm > 0.0, norm, 1.0), np.array([1.0, 0.0, 0.0, 0.0]))
    return np.where(unit[..., :1] < 0.0, -unit, unit)


KEPT = np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]])
"""For each index of a largest component, the indices of the other three, in order."""


def smallest_three(components: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each unit quaternion's "smallest three": the index of its largest |component| and the other three, in
    order, signed so that the left-out largest is positive (the formats store these and rebuild it)."""
    rows = np.arange(len(components))
    largest = np.argmax(np.abs(components), axis=1)
    signed = components * np.where(components[rows, largest] < 0.0, -1.0, 1.0)[:, None]
    return largest, np.take_along_axis(signed, KEPT[largest], axis=1)


def from_smallest_three(largest: np.ndarray, others: np.ndarray) -> np.ndarray:
    """Quaternion components from the largest one's index and the other three (see :func:`smallest_three`),
    the largest rebuilt, positive, from the unit norm."""
    components = np.zeros((len(others), 4))
    np.put_along_axis(components, KEPT[largest], others, axis=1)
    components[np.arange(len(others)), largest] = np.sqrt(np.maximum(0.0, 1.0 - np.sum(others * others, axis=1)))
    return components


def as_arrays(scene: GaussianScene | SplatArrays) -> SplatArrays:
    """A scene as numpy arrays (a ``GaussianScene``'s tensors are copied to the CPU)."""
    if isinstance(scene, SplatArrays):
        return scene
    values = {key: tensor.detach().cpu().numpy() for key, tensor in scene.tensors().items()}
    return SplatArrays(**values, extras=dict(scene.extras), ply_layout=None)


def make_arrays(
    path: PathLike,
    *,
    means: np.ndarray,
    quats: np.ndarray,
    log_scales: np.ndarray,
    opacity_logits: np.ndarray,
    sh_dc: np.ndarray,
    sh_rest: np.ndarray,
    drop_invalid: bool = False,
) -> SplatArrays:
    """The ``SplatArrays`` a reader returns: float32, shapes checked, and Gaussians with NaN/Inf values (or values
    beyond float32) an error naming ``path`` (or, with ``drop_invalid``, dropped with a warning), as for PLY files."""
    arrays = {
        "means": means,
        "quats": quats,
        "log_scales": log_scales,
        "opacity_logits": opacity_logits,
        "sh_dc": sh_dc,
        "sh_rest": sh_rest,
    }
    n = len(means)
    expected = {"means": (n, 3), "quats": (n, 4), "log_scales": (n, 3), "opacity_logits": (n,), "sh_dc": (n, 3)}
    sources = arrays
    with np.errstate(over="ignore", invalid="ignore"):
        arrays = {key: _own_float32(values) for key, values in sources.items()}
    for key, shape in expected.items():
        if arrays[key].shape != shape:
            raise SplatFormatError(path, f"{key} has shape {arrays[key].shape}, expected {shape}")
    if arrays["sh_rest"].ndim != 3 or arrays["sh_rest"].shape[0] != n or arrays["sh_rest"].shape[2] != 3:
        raise SplatFormatError(path, f"SH coefficients have shape {arrays['sh_rest'].shape}, expected ({n}, K, 3)")
    bad, why = _invalid_rows(arrays, sources)
    if bad.any():
        if not drop_invalid:
            raise SplatFormatError(path, f"{int(bad.sum())} of {n} Gaussians have {why}; {DROP_HINT}")
        warnings.warn(f"{os.fspath(path)}: dropped {int(bad.sum())} of {n} Gaussians with {why}", stacklevel=3)
        arrays = {key: values[~bad] for key, values in arrays.items()}
    return SplatArrays(**arrays, extras={}, ply_layout=None)


def _own_float32(values: np.ndarray) -> np.ndarray:
    """Contiguous, writable float32 (a view of a file's read-only bytes is copied: torch warns on those)."""
    out = np.ascontiguousarray(values, np.float32)
    return out if out.flags.writeable else out.copy()


def _invalid_rows(arrays: dict[str, np.ndarray], sources: dict[str, np.ndarray]) -> tuple[np.ndarray, str]:
    """The rows with a value float32 cannot hold, and what is wrong with them: NaN or Inf in the file, or finite
    values that decode beyond float32's range (so the file is not blamed for an Inf it does not hold)."""
    n = len(arrays["means"])
    bad, overflow = np.zeros(n, bool), np.zeros(n, bool)
    for key, values in arrays.items():
        if np.isfinite(values).all():
            continue
        rows = ~np.isfinite(values).reshape(n, -1).all(axis=1)
        bad |= rows
        with np.errstate(invalid="ignore"):
            source = np.asarray(sources[key], np.float64).reshape(n, -1)
        overflow |= rows & np.isfinite(source).all(axis=1)
    beyond = f"values that decode beyond float32's range (+-{FLOAT32_MAX:.3g})"
    if not overflow.any():
        return bad, "non-finite values (NaN or Inf)"
    return bad, beyond if overflow.sum() == bad.sum() else f"non-finite values (NaN or Inf) or {beyond}"


def over_budget(declared: int, file_size: int, what: str) -> str | None:
    """Why ``declared`` decoded bytes (``what``, from a header) are too many for a ``file_size``-byte file to hold,
    checked before anything is allocated (a decompression bomb or a corrupt header); None when they fit."""
    limit = min(MAX_DECOMPRESSED, max(DECODE_FLOOR, EXPANSION * file_size))
    if declared <= limit:
        return None
    return (
        f"declares {declared} bytes uncompressed ({what}), over the {limit}-byte limit for a {file_size}-byte file: "
        "a corrupt header or a decompression bomb"
    )


def inflate(path: PathLike, data: bytes, size: int) -> bytes:
    """The first ``size`` bytes that gzip ``data`` (read from ``path``) decompresses to, fewer when it holds fewer;
    a corrupt or truncated stream is one error naming the file. Nothing past ``size`` is inflated."""
    try:
        with gzip.GzipFile(fileobj=io.BytesIO(data)) as stream:
            return stream.read(size)
    except (OSError, EOFError, zlib.error) as exc:
        raise SplatFormatError(path, f"the gzip stream is corrupt or truncated ({exc})") from None


def require_finite(path: PathLike, arrays: SplatArrays, fmt: str) -> None:
    """A scene with NaN/Inf values is not written: it cannot be quantised (a NaN would spoil a whole range) and no
    reader here takes it back; an error naming the file that was to be written."""
    n = len(arrays)
    finite = np.ones(n, bool)
    for values in arrays.tensors().values():
        if not np.isfinite(values).all():
            finite &= np.isfinite(values).reshape(n, -1).all(axis=1)
    if not finite.all():
        bad = n - int(finite.sum())
        raise SplatFormatError(path, f"{bad} of {n} Gaussians have NaN or Inf values; {fmt} files hold finite ones")


def read_bytes(path: PathLike) -> bytes:
    """A whole file's bytes; a missing or unreadable file is one error naming it."""
    try:
        with open(path, "rb") as f:
            return f.read()
    except OSError as exc:
        raise SplatFormatError(path, f"cannot read the file ({exc.strerror or exc})") from None


def dropped_notes(arrays: SplatArrays, fmt: str, keeps_sh_degree: int) -> list[str]:
    """One line per kind of information a format that keeps SH up to ``keeps_sh_degree`` and no extra
    properties drops from ``arrays`` (nothing for what it only stores at lower precision)."""
    notes = []
    degree = sh_degree_from_rest(arrays.sh_rest.shape[1])
    if degree > keeps_sh_degree and np.any(arrays.sh_rest[:, (keeps_sh_degree + 1) ** 2 - 1 :]):
        notes.append(f"{fmt} keeps SH degree {keeps_sh_degree} at most: bands {keeps_sh_degree + 1}-{degree} dropped")
    if arrays.extras:
        notes.append(f"{fmt} keeps no extra properties: {', '.join(arrays.extras)} dropped")
    return notes
