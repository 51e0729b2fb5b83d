"""The INRIA 3DGS conventions every splat reader and writer shares: which PLY property holds which
Gaussian parameter, how the SH coefficients are laid out, and the DC colour constant.

Plain Python (no numpy or torch import), so the engine (``gaussians``), the PLY code (numpy only) and
the Blender edge (before torch is installed) take these facts from one place.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import numpy as np

SH_C0 = 0.28209479177387814
"""Degree-0 real spherical-harmonic constant: colour = 0.5 + SH_C0 * f_dc."""
SH_C1 = 0.4886025119029199
SH_C2 = (1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792, 0.5462742152960396)
SH_C3 = (
    -0.5900435899266435,
    2.890611442640554,
    -0.4570457994644658,
    0.3731763325901154,
    -0.4570457994644658,
    1.445305721320277,
    -0.5900435899266435,
)
"""The real SH constants of bands 1-3, in the reference 3DGS implementation's order."""

POSITION_NAMES = ("x", "y", "z")
NORMAL_NAMES = ("nx", "ny", "nz")
"""Optional normals; not a Gaussian parameter (kept as extras), written right after the positions."""
REST_PREFIX = "f_rest_"


def sh_terms(x: Any, y: Any, z: Any, degree: int) -> list[Any]:
    """The real SH basis of bands 1 to ``degree`` at unit directions (x, y, z): numpy arrays or torch tensors
    alike (plain arithmetic), so the renderer and the Blender edge's SH rotation evaluate one formula."""
    out = []
    if degree >= 1:
        out += [-SH_C1 * y, SH_C1 * z, -SH_C1 * x]
    if degree >= 2:
        xx, yy, zz, xy, yz, xz = x * x, y * y, z * z, x * y, y * z, x * z
        out += [SH_C2[0] * xy, SH_C2[1] * yz, SH_C2[2] * (2 * zz - xx - yy), SH_C2[3] * xz, SH_C2[4] * (xx - yy)]
    if degree >= 3:
        out += [
            SH_C3[0] * y * (3 * xx - yy),
            SH_C3[1] * xy * z,
            SH_C3[2] * y * (4 * zz - xx - yy),
            SH_C3[3] * z * (2 * zz - 3 * xx - 3 * yy),
            SH_C3[4] * x * (4 * zz - xx - yy),
            SH_C3[5] * z * (xx - yy),
            SH_C3[6] * x * (xx - 3 * yy),
        ]
    return out


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
