"""The rasterizer's footprint and compositing rules, in one torch-free place: every backend (torch, the numba port)
and Blender's splat display read them here; the C++ kernel (``render/csrc``) states them as constants, and the
backend-agreement tests hold it to these."""

TILE = 8
"""Pixels on each side of a compositing tile."""
ALPHA_MIN = 1.0 / 255.0
"""A splat's footprint is where its alpha reaches this (3DGS); fainter splats and pixels are skipped."""
ALPHA_MAX = 0.99
"""Alpha is clamped to this, so a single splat never makes a pixel fully opaque (3DGS)."""
T_MIN = 1e-4
"""A pixel stops before the splat that would bring its transmittance below this (3DGS)."""
EPS2D = 0.3
"""Screen-space dilation (px²) added to every 2D covariance, as in 3DGS (anti-aliasing floor)."""
FOV_CLAMP = 1.3
"""The EWA Jacobian is evaluated at most 30 % of tan(fov/2) outside the view frustum (3DGS, gsplat), which
bounds the footprints of Gaussians far off-screen."""
