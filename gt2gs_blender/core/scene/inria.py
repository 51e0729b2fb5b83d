"""The INRIA 3DGS conventions every splat reader and writer shares: which PLY property holds which
Gaussian parameter, how the SH coefficients are laid out, and the DC colour constant.

Plain Python (no numpy or torch import), so the engine (``gaussians``), the PLY code (numpy only) and
the Blender edge (before torch is installed) take these facts from one place.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import numpy as np

SH_C0 = 0.28209479177387814
"""Degree-0 real spherical-harmonic constant: colour = 0.5 + SH_C0 * f_dc."""

POSITION_NAMES = ("x", "y", "z")
NORMAL_NAMES = ("nx", "ny", "nz")
"""Optional normals; not a Gaussian parameter (kept as extras), written right after the positions."""
REST_PREFIX = "f_rest_"


def sh_coeff_count(degree: int) -> int:
    """Number of SH coefficients per colour channel for a degree (1, 4, 9, 16)."""
    return (degree + 1) ** 2


def sh_degree_from_rest(n_rest_per_channel: int) -> int:
    """SH degree from the number of f_rest coefficients per channel (0, 3, 8 or 15)."""
    for degree in range(4):
        if sh_coeff_count(degree) - 1 == n_rest_per_channel:
            return degree
    raise ValueError(f"{n_rest_per_channel} f_rest coefficients per channel is not an SH degree 0-3 layout")


def core_groups(k: int) -> dict[str, list[str]]:
    """Scene field -> its PLY properties in canonical INRIA order (f_rest channel-major, R first)."""
    return {
        "means": list(POSITION_NAMES),
        "sh_dc": [f"f_dc_{i}" for i in range(3)],
        "sh_rest": [f"{REST_PREFIX}{i}" for i in range(3 * k)],
        "opacity_logits": ["opacity"],
        "log_scales": [f"scale_{i}" for i in range(3)],
        "quats": [f"rot_{i}" for i in range(4)],
    }


def core_property_names(k: int) -> list[str]:
    """The Gaussian parameters' PLY names in canonical INRIA order (positions first)."""
    return [name for names in core_groups(k).values() for name in names]


REQUIRED = tuple(core_property_names(0))
"""The properties every 3DGS PLY has (x y z, f_dc_*, opacity, scale_*, rot_*)."""


def rest_per_channel(names: Iterable[str]) -> int | None:
    """K (f_rest per channel) when ``names`` are exactly f_rest_0 .. f_rest_<3K-1> of SH degree 0-3, else None."""
    names = list(names)
    for degree in range(4):
        k = sh_coeff_count(degree) - 1
        if len(names) == 3 * k and set(names) == {f"{REST_PREFIX}{i}" for i in range(3 * k)}:
            return k
    return None


def tensor_view(key: str, storage: np.ndarray) -> np.ndarray:
    """View (N, columns) in PLY order with the shape of scene field ``key``: sh_rest (N,3K) -> (N,K,3)."""
    n = storage.shape[0]
    if key == "sh_rest":
        return storage.reshape(n, 3, storage.shape[1] // 3).transpose(0, 2, 1)
    if key == "opacity_logits":
        return storage.reshape(n)
    return storage
