"""Real spherical harmonics up to degree 3, evaluated as in the reference 3DGS implementation."""

from __future__ import annotations

import torch

from ..scene.gaussians import SH_C0

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


def sh_basis(dirs: torch.Tensor, degree: int) -> torch.Tensor:
    """Basis values (..., (degree+1)^2) for unit directions (..., 3)."""
    x, y, z = dirs.unbind(-1)
    out = [torch.full_like(x, SH_C0)]
    if degree >= 1:
        out += [-SH_C1 * y, SH_C1 * z, -SH_C1 * x]
    if degree >= 2:
        xx, yy, zz, xy, yz, xz = x * x, y * y, z * z, x * y, y * z, x * z
        out += [
            SH_C2[0] * xy,
            SH_C2[1] * yz,
            SH_C2[2] * (2 * zz - xx - yy),
            SH_C2[3] * xz,
            SH_C2[4] * (xx - yy),
        ]
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
    return torch.stack(out, dim=-1)


def sh0_to_rgb(dc: torch.Tensor) -> torch.Tensor:
    """View-independent RGB of the DC band, clamped at 0."""
    return (0.5 + SH_C0 * dc).clamp_min(0.0)


def eval_sh(coeffs: torch.Tensor, dirs: torch.Tensor, degree: int) -> torch.Tensor:
    """RGB (..., 3) = 0.5 + sum_k basis_k * coeffs[..., k, :], clamped at 0 like 3DGS.

    ``coeffs`` is (..., K, 3) with K >= (degree+1)^2; bands above ``degree`` are never evaluated.
    Degree 0 skips the direction entirely (the colour is view-independent).
    """
    if degree == 0:
        return sh0_to_rgb(coeffs[..., 0, :])
    n = (degree + 1) ** 2
    basis = sh_basis(dirs, degree)
    rgb = torch.einsum("...k,...kc->...c", basis, coeffs[..., :n, :])
    return (rgb + 0.5).clamp_min(0.0)
