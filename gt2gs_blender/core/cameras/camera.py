"""The pinhole camera every part of the engine uses: OpenCV axes (x right, y down, z forward), a
world->camera 4x4 ``viewmat`` and pixel intrinsics with pixel centres at +0.5."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

_ORTHO_TOL = 1e-4


MAX_IMAGE_SIDE = 65536
"""Largest image width or height a camera may have (Blender's limit): larger sizes in a camera file
are corruption, and rendering them would try to allocate terabytes."""


# ---------------------------------------------------------------------------------------------------
# The camera
# ---------------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Camera:
    """A pinhole camera: world->camera pose (OpenCV axes) and intrinsics in pixels.

    A camera-frame point (x, y, z) projects to u = fx*x/z + cx, v = fy*y/z + cy; pixel (row i, col j)
    has its centre at (j + 0.5, i + 0.5). ``world_to_cam`` is stored as a read-only float64 copy.
    """

    world_to_cam: np.ndarray
    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int
    name: str = ""

    def __post_init__(self) -> None:
        try:
            viewmat = np.array(self.world_to_cam, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"world_to_cam must be a 4x4 array of numbers: {exc}") from exc
        _check_viewmat(viewmat)
        viewmat.flags.writeable = False
        object.__setattr__(self, "world_to_cam", viewmat)
        for key in ("fx", "fy", "cx", "cy"):
            object.__setattr__(self, key, _finite_float(getattr(self, key), f"camera {key}"))
        if self.fx <= 0 or self.fy <= 0:
            raise ValueError(f"camera focal lengths must be positive, got fx={self.fx}, fy={self.fy}")
        for key in ("width", "height"):
            object.__setattr__(self, key, _positive_int(getattr(self, key), f"camera {key}"))
        if max(self.width, self.height) > MAX_IMAGE_SIDE:
            raise ValueError(f"camera image size {self.width} x {self.height} exceeds {MAX_IMAGE_SIDE} px per side")
        object.__setattr__(self, "name", str(self.name))

    @classmethod
    def from_cam_to_world(
        cls,
        R_c2w: np.ndarray,
        center: Sequence[float],
        fx: float,
        fy: float,
        cx: float,
        cy: float,
        width: int,
        height: int,
        name: str = "",
    ) -> Camera:
        """A camera from its camera->world rotation (columns = right, down, forward) and centre."""
        R = np.asarray(R_c2w, dtype=np.float64)
        c = np.asarray(center, dtype=np.float64)
        if R.shape != (3, 3) or c.shape != (3,):
            raise ValueError(f"rotation must be 3x3 and centre 3-vector, got {R.shape} and {c.shape}")
        viewmat = np.eye(4)
        viewmat[:3, :3] = R.T
        viewmat[:3, 3] = -R.T @ c
        return cls(viewmat, fx, fy, cx, cy, width, height, name)

    @property
    def K(self) -> np.ndarray:
        """Intrinsic matrix (3x3)."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def cam_to_world(self) -> np.ndarray:
        """Camera->world 4x4 (the exact rigid inverse of ``world_to_cam``)."""
        out = np.eye(4)
        out[:3, :3] = self.world_to_cam[:3, :3].T
        out[:3, 3] = self.center
        return out

    @property
    def center(self) -> np.ndarray:
        """Camera centre in world coordinates."""
        return -self.world_to_cam[:3, :3].T @ self.world_to_cam[:3, 3]

    @property
    def forward(self) -> np.ndarray:
        """World direction of the optical axis (+z of the camera)."""
        return self.world_to_cam[2, :3].copy()

    @property
    def fov_x(self) -> float:
        """Horizontal field of view in radians."""
        return 2.0 * math.atan(self.width / (2.0 * self.fx))

    @property
    def fov_y(self) -> float:
        """Vertical field of view in radians."""
        return 2.0 * math.atan(self.height / (2.0 * self.fy))

    def scaled(self, factor: float) -> Camera:
        """The same camera for an image resized by ``factor`` (e.g. 0.5, 0.25).

        Sizes are rounded; intrinsics scale by the actual per-axis size ratio, which equals
        ``factor`` when the size divides evenly and otherwise matches what an image resize does.
        """
        if not (math.isfinite(factor) and factor > 0):
            raise ValueError(f"scale factor must be positive, got {factor}")
        width = max(1, round(self.width * factor))
        height = max(1, round(self.height * factor))
        sx, sy = width / self.width, height / self.height
        return Camera(
            self.world_to_cam, self.fx * sx, self.fy * sy, self.cx * sx, self.cy * sy, width, height, self.name
        )

    def cropped(self, width: int, height: int) -> Camera:
        """The same camera with its image cut (or grown) to ``width`` x ``height`` about its centre; the same
        pixels where the two overlap when the sizes differ by even counts."""
        return Camera(
            self.world_to_cam,
            self.fx,
            self.fy,
            self.cx + (width - self.width) / 2.0,
            self.cy + (height - self.height) / 2.0,
            width,
            height,
            self.name,
        )

    def project(self, points_world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixel coordinates (N,2) and camera depths (N,) of world points (N,3).

        ``uv`` is meaningful only where ``depth > 0`` (in front of the camera).
        """
        pts = np.asarray(points_world, dtype=np.float64).reshape(-1, 3)
        cam = pts @ self.world_to_cam[:3, :3].T + self.world_to_cam[:3, 3]
        depth = cam[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            uv = np.stack([self.fx * cam[:, 0] / depth + self.cx, self.fy * cam[:, 1] / depth + self.cy], axis=1)
        return uv, depth


def _finite_float(value: Any, what: str) -> float:
    """``value`` as a finite float, else ValueError naming ``what``."""
    try:
        out = float(value)
    except (TypeError, ValueError):
        out = math.nan
    if not math.isfinite(out):
        raise ValueError(f"{what} must be a finite number, got {value!r}")
    return out


def _positive_int(value: Any, what: str) -> int:
    """``value`` as a positive int (integral floats accepted), else ValueError naming ``what``."""
    integral = isinstance(value, (int, np.integer)) and not isinstance(value, bool)
    integral = integral or (isinstance(value, (float, np.floating)) and float(value).is_integer())
    if not integral or value <= 0:
        raise ValueError(f"{what} must be a positive integer, got {value!r}")
    return int(value)


def _check_viewmat(viewmat: np.ndarray) -> None:
    """Raise ValueError unless ``viewmat`` is a finite rigid 4x4 transform (proper rotation)."""
    if viewmat.shape != (4, 4):
        raise ValueError(f"world_to_cam must be 4x4, got shape {viewmat.shape}")
    if not np.all(np.isfinite(viewmat)):
        raise ValueError("world_to_cam contains non-finite values")
    if np.abs(viewmat[3] - [0.0, 0.0, 0.0, 1.0]).max() > _ORTHO_TOL:
        raise ValueError(f"world_to_cam last row must be (0, 0, 0, 1), got {viewmat[3].tolist()}")
    R = viewmat[:3, :3]
    error = np.abs(R @ R.T - np.eye(3)).max()
    if error > _ORTHO_TOL:
        raise ValueError(f"world_to_cam rotation is not orthonormal (max |R R^T - I| = {error:.2e})")
    if np.linalg.det(R) < 0:
        raise ValueError("world_to_cam rotation is a reflection (det < 0): check the axis convention")


def stack_cameras(
    cameras: Sequence[Camera],
    device: torch.device | str | None = None,
    dtype: torch.dtype = torch.float32,
) -> tuple[torch.Tensor, torch.Tensor, int, int]:
    """Batch cameras for the rasterizer: viewmats (C,4,4), Ks (C,3,3), width, height."""
    if not cameras:
        raise ValueError("stack_cameras needs at least one camera")
    sizes = {(c.width, c.height) for c in cameras}
    if len(sizes) != 1:
        raise ValueError(f"cameras must share one image size to be batched, got {sorted(sizes)}")
    viewmats = torch.tensor(np.stack([c.world_to_cam for c in cameras]), dtype=dtype, device=device)
    Ks = torch.tensor(np.stack([c.K for c in cameras]), dtype=dtype, device=device)
    width, height = sizes.pop()
    return viewmats, Ks, width, height


def camera_extent(cameras: Sequence[Camera]) -> float:
    """3DGS's scene extent: 1.1 x the largest distance of a camera centre from their mean."""
    centers = np.stack([c.center for c in cameras])
    return 1.1 * float(np.linalg.norm(centers - centers.mean(axis=0), axis=1).max())
