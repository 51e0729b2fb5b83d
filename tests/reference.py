"""A float64 dense per-pixel Gaussian renderer written plainly: the oracle for every backend.

No tiles, no culling boxes, no chunking: every Gaussian in front of the near plane is evaluated at
every pixel centre in depth order with the engine's alpha rules. The EWA Jacobian's frustum clamp is
the published one (``frustum_clamp``), written from the 3DGS / gsplat rule rather than copied from the
engine, so an engine that drifts from it fails here. It also marks pixels where a rule decision is
within rounding distance of its threshold, where float32 backends may legitimately decide the other way.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

C0 = 0.28209479177387814
C1 = 0.4886025119029199
C2 = [1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792, 0.5462742152960396]
C3 = [
    -0.5900435899266435,
    2.890611442640554,
    -0.4570457994644658,
    0.3731763325901154,
    -0.4570457994644658,
    1.445305721320277,
    -0.5900435899266435,
]
NEAR = 0.01
BAND = 2e-4  # relative distance to a threshold below which a decision counts as ambiguous


@dataclass
class RefImage:
    color: np.ndarray  # (H, W, 3)
    depth: np.ndarray  # (H, W)
    alpha: np.ndarray  # (H, W)
    ambiguous: np.ndarray  # (H, W) bool


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(q)
    w, x, y, z = q / n if n > 1e-12 else np.array([1.0, 0, 0, 0])
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def sh_color(coeffs: np.ndarray, d: np.ndarray, degree: int) -> np.ndarray:
    """RGB from SH coefficients (K, 3) for a unit direction d, 3DGS basis and +0.5 offset, clamped at 0."""
    x, y, z = d
    basis = [C0]
    if degree >= 1:
        basis += [-C1 * y, C1 * z, -C1 * x]
    if degree >= 2:
        basis += [
            C2[0] * x * y,
            C2[1] * y * z,
            C2[2] * (2 * z * z - x * x - y * y),
            C2[3] * x * z,
            C2[4] * (x * x - y * y),
        ]
    if degree >= 3:
        basis += [
            C3[0] * y * (3 * x * x - y * y),
            C3[1] * x * y * z,
            C3[2] * y * (4 * z * z - x * x - y * y),
            C3[3] * z * (2 * z * z - 3 * x * x - 3 * y * y),
            C3[4] * x * (4 * z * z - x * x - y * y),
            C3[5] * z * (x * x - y * y),
            C3[6] * x * (x * x - 3 * y * y),
        ]
    rgb = sum(b * coeffs[i] for i, b in enumerate(basis)) + 0.5
    return np.maximum(rgb, 0.0)


def frustum_clamp(x_over_z: float, y_over_z: float, k: np.ndarray, width: int, height: int) -> np.ndarray:
    """x/z, y/z clamped where the EWA Jacobian is evaluated: the published 3DGS rule, not the engine's.

    INRIA 3DGS clamps to +-1.3 tan(fov/2) with tan(fov_x/2) = W / (2 fx); gsplat's ``persp_proj``
    (the rule followed here) shifts that box by the principal point: x/z in
    [-(cx / fx + 0.3 tan_fov_x), (W - cx) / fx + 0.3 tan_fov_x], the same when cx = W / 2.
    """
    fx, fy, cx, cy = k[0, 0], k[1, 1], k[0, 2], k[1, 2]
    tan_fov_x, tan_fov_y = 0.5 * width / fx, 0.5 * height / fy
    x = min(max(x_over_z, -(cx / fx + 0.3 * tan_fov_x)), (width - cx) / fx + 0.3 * tan_fov_x)
    y = min(max(y_over_z, -(cy / fy + 0.3 * tan_fov_y)), (height - cy) / fy + 0.3 * tan_fov_y)
    return np.array([x, y])


def render_reference(means, quats, scales, opacities, colors, viewmat, k, width, height, sh_degree=None):
    """Render one camera. Inputs are numpy arrays (cast to float64); colors (N,D) or SH (N,K,3)."""
    means, quats, scales, opacities, colors, viewmat, k = (
        np.asarray(a, dtype=np.float64) for a in (means, quats, scales, opacities, colors, viewmat, k)
    )
    rot, trans = viewmat[:3, :3], viewmat[:3, 3]
    fx, fy, cx, cy = k[0, 0], k[1, 1], k[0, 2], k[1, 2]
    center = -rot.T @ trans
    ys, xs = np.mgrid[0:height, 0:width].astype(np.float64) + 0.5
    splats = []
    for i in range(len(means)):
        p = rot @ means[i] + trans
        if not p[2] > NEAR:
            continue
        r = quat_to_matrix(quats[i]) @ np.diag(scales[i])
        cov_cam = rot @ (r @ r.T) @ rot.T
        tx, ty = p[2] * frustum_clamp(p[0] / p[2], p[1] / p[2], k, width, height)
        jac = np.array([[fx / p[2], 0, -fx * tx / p[2] ** 2], [0, fy / p[2], -fy * ty / p[2] ** 2]])
        cov2 = jac @ cov_cam @ jac.T + 0.3 * np.eye(2)
        conic = np.linalg.inv(cov2)
        u, v = fx * p[0] / p[2] + cx, fy * p[1] / p[2] + cy
        if sh_degree is None:
            rgb = colors[i]
        else:
            d = means[i] - center
            rgb = sh_color(colors[i], d / np.linalg.norm(d), sh_degree)
        splats.append((p[2], u, v, conic, opacities[i], rgb))
    splats.sort(key=lambda s: s[0])
    color = np.zeros((height, width, colors.shape[1] if sh_degree is None else 3))
    depth = np.zeros((height, width))
    trans_map = np.ones((height, width))
    done = np.zeros((height, width), dtype=bool)
    ambiguous = np.zeros((height, width), dtype=bool)
    for z, u, v, conic, o, rgb in splats:
        dx, dy = u - xs, v - ys
        power = -0.5 * (conic[0, 0] * dx * dx + conic[1, 1] * dy * dy) - conic[0, 1] * dx * dy
        raw = o * np.exp(power)
        alpha = np.minimum(0.99, raw)
        near_cut = np.abs(raw - 1.0 / 255.0) < BAND / 255.0
        use = (alpha >= 1.0 / 255.0) & ~done
        test_t = trans_map * (1.0 - alpha)
        stop = use & (test_t < 1e-4)
        ambiguous |= ~done & (near_cut | (use & (np.abs(test_t - 1e-4) < BAND * 1e-4)))
        done |= stop
        use &= ~stop
        w = np.where(use, alpha * trans_map, 0.0)
        color += w[..., None] * rgb
        depth += w * z
        trans_map = np.where(use, test_t, trans_map)
    return RefImage(color=color, depth=depth, alpha=1.0 - trans_map, ambiguous=ambiguous)


def support_radius(opacity: float, sigma: float) -> float:
    """Distance from the centre of an isotropic 2D Gaussian (std sigma px) where alpha reaches 1/255."""
    return sigma * math.sqrt(2.0 * math.log(255.0 * opacity))
