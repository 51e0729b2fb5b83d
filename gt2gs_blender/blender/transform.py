"""Bake a 4x4 affine transform into raw Gaussian parameters (numpy only, no bpy, no torch).

A Gaussian stays a Gaussian under any affine map x -> A x + t: its mean moves to A m + t and its
covariance becomes A Σ Aᵀ. Two paths compute the new rotation and scales:

- a *similarity* (A = s·R with s > 0, R a rotation): the quaternion is multiplied on the left by
  R's quaternion and log(s) is added to every log-scale. Exact, keeps each Gaussian's axis order and
  its (possibly unnormalised) quaternion norm.
- anything else (non-uniform scale, shear, mirror): A·R·S is decomposed by SVD into U Σ Vᵀ, so that
  A Σ Aᵀ = U Σ² Uᵀ; U becomes the rotation (det fixed to +1) and Σ the scales. Exact for the
  covariance; the axes may come out in another order.

View-dependent colour turns with the scene: the SH bands of degree ≥ 1 are transformed by the
orthogonal part Q of A (Q = A/s for a similarity, the polar factor otherwise), so that the colour
seen along direction Q·d after baking equals the colour seen along d before. The band matrices are
fitted on fixed sample directions with the same real-SH basis the rasterizer evaluates.

Normals (``nx, ny, nz``) turn with Q for a similarity and with A⁻ᵀ (keeping their length) otherwise.
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from ..core.rotations import quats_to_matrices
from ..core.scene.inria import NORMAL_NAMES, SH_C0, sh_degree_from_rest, sh_terms

if TYPE_CHECKING:
    from ..core.scene.arrays import SplatArrays

SIMILARITY_TOLERANCE = 1e-6
"""Relative deviation of AᵀA from s²·I below which A counts as a similarity."""

GENERAL_NOTE = (
    "the transform has a non-uniform scale, shear or mirror: covariances were baked "
    "exactly, view-dependent colour (SH) was turned by the transform's rotation part"
)


class TransformError(ValueError):
    """The transform cannot be baked (singular or not finite)."""


def is_identity(matrix: np.ndarray, tol: float = 1e-12) -> bool:
    """Whether ``matrix`` is the 4x4 identity within ``tol`` (then nothing needs baking)."""
    return bool(np.allclose(np.asarray(matrix, np.float64), np.eye(4), rtol=0.0, atol=tol))


def similarity_parts(linear: np.ndarray) -> tuple[float, np.ndarray] | None:
    """(s, R) when ``linear`` = s·R with s > 0 and R a proper rotation, else None."""
    a = np.asarray(linear, np.float64)
    if np.linalg.det(a) <= 0:
        return None
    gram = a.T @ a
    s2 = np.trace(gram) / 3.0
    if s2 <= 0 or np.abs(gram - s2 * np.eye(3)).max() > SIMILARITY_TOLERANCE * s2:
        return None
    s = float(np.sqrt(s2))
    return s, _nearest_rotation(a / s)


def bake(scene: SplatArrays, matrix: np.ndarray) -> tuple[SplatArrays, list[str]]:
    """A copy of ``scene`` with the 4x4 ``matrix`` (applied to column vectors) baked in, and what the
    baking had to approximate, for the user (nothing for a similarity). ``scene`` is not modified."""
    linear, offset = _affine_parts(matrix)
    parts = similarity_parts(linear)
    if parts is not None:
        s, rot = parts
        quats = _quat_multiply(_quat_from_matrix(rot)[None, :], scene.quats.astype(np.float64))
        log_scales = scene.log_scales.astype(np.float64) + np.log(s)
        orth, normal_rotation, notes = rot, rot, []
    else:
        quats, log_scales = _bake_general(scene.quats, scene.log_scales, linear)
        u, _, vt = np.linalg.svd(linear)
        orth, normal_rotation, notes = u @ vt, None, [GENERAL_NOTE]
    baked = replace(
        scene,
        means=(scene.means.astype(np.float64) @ linear.T + offset).astype(np.float32),
        quats=quats.astype(np.float32),
        log_scales=log_scales.astype(np.float32),
        sh_rest=rotate_sh_rest(scene.sh_rest, orth),
        extras=_turned_normals(scene.extras, linear, normal_rotation),
    )
    return baked, notes


def _affine_parts(matrix: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(A, t) of a finite, non-singular 4x4 affine ``matrix``; ``TransformError`` otherwise."""
    m = np.asarray(matrix, np.float64)
    if m.shape != (4, 4) or not np.isfinite(m).all():
        raise TransformError("the object transform is not a finite 4x4 matrix")
    if np.abs(m[3] - (0, 0, 0, 1)).max() > 1e-9:
        raise TransformError("the object transform has a perspective part and cannot be baked into splats")
    linear, offset = m[:3, :3], m[:3, 3]
    det = np.linalg.det(linear)
    if not abs(det) > 1e-12 * max(np.abs(linear).max(), 1e-300) ** 3:
        raise TransformError("the object transform is singular (a zero scale) and cannot be baked into splats")
    return linear, offset


def _turned_normals(
    extras: dict[str, np.ndarray], linear: np.ndarray, rotation: np.ndarray | None
) -> dict[str, np.ndarray]:
    """``extras`` with float normals (nx, ny, nz) turned by ``rotation``, or by A⁻ᵀ keeping their length."""
    if not all(p in extras and extras[p].dtype.kind == "f" for p in NORMAL_NAMES):
        return extras
    n = np.stack([extras[p] for p in NORMAL_NAMES], axis=1).astype(np.float64)
    if rotation is not None:
        turned = n @ rotation.T
    else:
        turned = n @ np.linalg.inv(linear)  # rows: (A^-T n)^T = n^T A^-1
        length = np.linalg.norm(n, axis=1, keepdims=True)
        new_length = np.linalg.norm(turned, axis=1, keepdims=True)
        turned = np.where(new_length > 0, turned * (length / np.where(new_length > 0, new_length, 1)), 0.0)
    return {**extras, **{p: np.ascontiguousarray(turned[:, i], extras[p].dtype) for i, p in enumerate(NORMAL_NAMES)}}


def _bake_general(quats: np.ndarray, log_scales: np.ndarray, linear: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotations and log-scales of A·R·S by SVD (U with det +1, Σ), for a transform that is no similarity."""
    rot = quats_to_matrices(quats)
    scaled = (linear[None] @ rot) * np.exp(log_scales.astype(np.float64))[:, None, :]
    u, sigma, _ = np.linalg.svd(scaled)
    flip = np.linalg.det(u) < 0
    u[flip, :, 2] *= -1.0
    with np.errstate(divide="ignore"):
        return quats_from_matrices(u), np.log(sigma)


# -- quaternions (w, x, y, z) ---------------------------------------------------------------------------


def quats_from_matrices(mats: np.ndarray) -> np.ndarray:
    """(N,3,3) proper rotation matrices to (N,4) unit quaternions with w ≥ 0 (Shepperd's method)."""
    m = np.asarray(mats, np.float64)
    trace = m[:, 0, 0] + m[:, 1, 1] + m[:, 2, 2]
    diag = np.stack([trace, m[:, 0, 0], m[:, 1, 1], m[:, 2, 2]], axis=1)
    pick = np.argmax(diag, axis=1)
    q = np.empty((len(m), 4))
    for case in range(4):
        sel = pick == case
        if not sel.any():
            continue
        r = m[sel]
        if case == 0:
            t = np.sqrt(1.0 + trace[sel]) * 2
            q[sel] = np.stack(
                [0.25 * t, (r[:, 2, 1] - r[:, 1, 2]) / t, (r[:, 0, 2] - r[:, 2, 0]) / t, (r[:, 1, 0] - r[:, 0, 1]) / t],
                axis=1,
            )
        elif case == 1:
            t = np.sqrt(1.0 + r[:, 0, 0] - r[:, 1, 1] - r[:, 2, 2]) * 2
            q[sel] = np.stack(
                [(r[:, 2, 1] - r[:, 1, 2]) / t, 0.25 * t, (r[:, 0, 1] + r[:, 1, 0]) / t, (r[:, 0, 2] + r[:, 2, 0]) / t],
                axis=1,
            )
        elif case == 2:
            t = np.sqrt(1.0 + r[:, 1, 1] - r[:, 0, 0] - r[:, 2, 2]) * 2
            q[sel] = np.stack(
                [(r[:, 0, 2] - r[:, 2, 0]) / t, (r[:, 0, 1] + r[:, 1, 0]) / t, 0.25 * t, (r[:, 1, 2] + r[:, 2, 1]) / t],
                axis=1,
            )
        else:
            t = np.sqrt(1.0 + r[:, 2, 2] - r[:, 0, 0] - r[:, 1, 1]) * 2
            q[sel] = np.stack(
                [(r[:, 1, 0] - r[:, 0, 1]) / t, (r[:, 0, 2] + r[:, 2, 0]) / t, (r[:, 1, 2] + r[:, 2, 1]) / t, 0.25 * t],
                axis=1,
            )
    q[q[:, 0] < 0] *= -1.0
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def _quat_from_matrix(rot: np.ndarray) -> np.ndarray:
    """The unit quaternion (w ≥ 0) of one 3x3 rotation matrix."""
    return quats_from_matrices(rot[None])[0]


def _quat_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a ⊗ b of (N,4) or broadcastable (1,4) quaternions (w, x, y, z)."""
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


def _nearest_rotation(a: np.ndarray) -> np.ndarray:
    """The proper rotation closest to ``a`` (its polar factor, det forced to +1)."""
    u, _, vt = np.linalg.svd(a)
    r = u @ vt
    if np.linalg.det(r) < 0:
        u[:, 2] *= -1.0
        r = u @ vt
    return r


# -- spherical harmonics --------------------------------------------------------------------------------


def sh_basis(dirs: np.ndarray, degree: int) -> np.ndarray:
    """Real SH basis (M, (degree+1)^2) at unit directions (M,3), the 3DGS convention (as core's sh_basis)."""
    x, y, z = np.asarray(dirs, np.float64).T
    return np.stack([np.full_like(x, SH_C0), *sh_terms(x, y, z, degree)], axis=-1)


def _sample_directions(count: int = 64) -> np.ndarray:
    """Fibonacci-sphere directions: deterministic and well spread."""
    i = np.arange(count) + 0.5
    z = 1 - 2 * i / count
    r = np.sqrt(1 - z * z)
    phi = np.pi * (1 + 5**0.5) * i
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def sh_band_matrices(orth: np.ndarray, degree: int) -> list[np.ndarray]:
    """For l = 1..degree, D_l with Σ_k (D_l c)_k Y_k(Q d) = Σ_k c_k Y_k(d) for every direction d."""
    dirs = _sample_directions()
    turned_back = dirs @ np.asarray(orth, np.float64)  # rows: (Qᵀ d)ᵀ = dᵀ Q
    basis_new, basis_old = sh_basis(dirs, degree), sh_basis(turned_back, degree)
    out = []
    for band in range(1, degree + 1):
        idx = slice(band * band, (band + 1) ** 2)
        out.append(np.linalg.lstsq(basis_new[:, idx], basis_old[:, idx], rcond=None)[0])
    return out


def rotate_sh_rest(sh_rest: np.ndarray, orth: np.ndarray) -> np.ndarray:
    """Transform the f_rest coefficients (N,K,3) so the view-dependent colour turns with ``orth``."""
    k = sh_rest.shape[1]
    if k == 0:
        return sh_rest.copy()
    degree = sh_degree_from_rest(k)
    out = np.empty_like(sh_rest)
    for band, d in enumerate(sh_band_matrices(orth, degree), start=1):
        idx = slice(band * band - 1, (band + 1) ** 2 - 1)
        out[:, idx, :] = np.einsum("ij,njc->nic", d, sh_rest[:, idx, :].astype(np.float64)).astype(sh_rest.dtype)
    return out
