"""LLFF captures (``poses_bounds.npy`` + images): cameras converted to the OpenCV frame at the edge."""

from __future__ import annotations

import math
import os
import tokenize
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import CameraFileError
from .camera import Camera

_IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")


# ---------------------------------------------------------------------------------------------------
# LLFF poses_bounds.npy
# ---------------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class LLFFData:
    """An LLFF capture: cameras (file order), near/far bounds (N,2) and the matching image files."""

    cameras: list[Camera]
    bounds: np.ndarray
    image_paths: list[Path]


def load_llff(path: str | os.PathLike, *, downscale: float = 1.0, image_dir: str | None = None) -> LLFFData:
    """Cameras from LLFF ``poses_bounds.npy`` (the file or the scene folder holding it).

    Rows are 3x5 [R | t | (h, w, f)] flattened, then near, far; R's columns are the camera's
    (down, right, back) axes in world. Poses are kept in the file's world (no recentring or
    rescaling), so camera centres equal the t column. Intrinsics are for images ``downscale``
    times smaller (``images_8`` -> 8). ``image_dir`` (relative to the scene folder) defaults to
    ``images_{downscale}`` (``images`` at 1); its files must match the poses in count.
    """
    npy = Path(path) / "poses_bounds.npy" if Path(path).is_dir() else Path(path)
    if not (math.isfinite(downscale) and downscale > 0):
        raise ValueError(f"downscale must be positive, got {downscale}")
    table = _read_poses_bounds(npy)
    poses = table[:, :15].reshape(-1, 3, 5)
    cameras = [_llff_camera(npy, i, pose, downscale) for i, pose in enumerate(poses)]
    bounds = table[:, 15:17].copy()
    return LLFFData(cameras, bounds, _llff_images(npy, len(cameras), downscale, image_dir))


def _read_poses_bounds(npy: Path) -> np.ndarray:
    """The N x 17 float64 table of a poses_bounds.npy, validated.

    The header is checked before the data is loaded, so a corrupt header cannot make numpy allocate
    the (possibly terabytes of) data it promises; numpy's header parser raises several exception
    types on garbage (ValueError, EOFError, SyntaxError, tokenize.TokenError), all reported alike.
    """
    try:
        with open(npy, "rb") as f:
            version = np.lib.format.read_magic(f)
            if version not in ((1, 0), (2, 0)):
                raise ValueError(f"unsupported .npy format version {version}")
            read_header = (
                np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
            )
            shape, _, dtype = read_header(f)
            data_bytes = os.fstat(f.fileno()).st_size - f.tell()
        if len(shape) != 2 or shape[0] == 0 or shape[1] != 17:
            raise ValueError(f"expected an N x 17 array (3x5 pose + near, far), got shape {shape}")
        if dtype.kind not in "iuf":
            raise ValueError(f"expected real numbers, got dtype {dtype}")
        if shape[0] * shape[1] * dtype.itemsize > data_bytes:
            raise ValueError(
                f"truncated: the header promises a {shape[0]} x 17 array but only {data_bytes} bytes of data follow"
            )
        table = np.load(npy, allow_pickle=False)
    except (OSError, ValueError, EOFError, SyntaxError, tokenize.TokenError) as exc:
        raise CameraFileError(npy, f"cannot read poses_bounds.npy: {exc}") from exc
    table = table.astype(np.float64)
    if not np.all(np.isfinite(table)):
        raise CameraFileError(npy, "contains non-finite values")
    return table


def _llff_camera(npy: Path, index: int, pose: np.ndarray, downscale: float) -> Camera:
    """One LLFF 3x5 pose -> OpenCV camera: right = col 1, down = col 0, forward = -col 2."""
    h, w, f = pose[:, 4]
    if min(h, w, f) <= 0:
        raise CameraFileError(npy, f"pose {index}: image height, width and focal must be positive, got {h}, {w}, {f}")
    width, height = max(1, round(w / downscale)), max(1, round(h / downscale))
    R_c2w = np.stack([pose[:, 1], pose[:, 0], -pose[:, 2]], axis=1)
    sx, sy = width / w, height / h
    try:
        return Camera.from_cam_to_world(
            R_c2w, pose[:, 3], f * sx, f * sy, width / 2.0, height / 2.0, width, height, f"{index:03d}"
        )
    except ValueError as exc:
        raise CameraFileError(npy, f"pose {index}: {exc}") from exc


def _llff_images(npy: Path, count: int, downscale: float, image_dir: str | None) -> list[Path]:
    """Sorted images of the capture's image folder; [] when the default folder is absent."""
    if image_dir is None:
        if downscale != int(downscale):
            return []
        folder = npy.parent / ("images" if downscale == 1 else f"images_{int(downscale)}")
        if not folder.is_dir():
            return []
    else:
        folder = npy.parent / image_dir
        if not folder.is_dir():
            raise CameraFileError(folder, "image folder does not exist")
    images = sorted(p for p in folder.iterdir() if p.suffix.lower() in _IMAGE_SUFFIXES)
    if len(images) != count:
        raise CameraFileError(folder, f"has {len(images)} images but {npy.name} has {count} poses")
    return images
