"""Real spherical harmonics up to degree 3, evaluated as in the reference 3DGS implementation."""

from __future__ import annotations

import torch

from ..scene.inria import SH_C0, sh_terms


def sh_basis(dirs: torch.Tensor, degree: int) -> torch.Tensor:
    """Basis values (..., (degree+1)^2) for unit directions (..., 3)."""
    x, y, z = dirs.unbind(-1)
    return torch.stack([torch.full_like(x, SH_C0), *sh_terms(x, y, z, degree)], dim=-1)


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
