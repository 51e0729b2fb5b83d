"""COLMAP sparse models (text or binary): cameras, and the points that can seed a fit."""

from __future__ import annotations

import math
import os
import struct
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import CameraFileError
from ..rotations import DEGENERATE_NORM, quats_to_matrices
from .camera import Camera

# ---------------------------------------------------------------------------------------------------
# COLMAP sparse models
# ---------------------------------------------------------------------------------------------------
# model id -> (name, parameter count); the supported pinhole-like models (distortion ignored).
_COLMAP_MODELS = {
    0: ("SIMPLE_PINHOLE", 3),
    1: ("PINHOLE", 4),
    2: ("SIMPLE_RADIAL", 4),
    3: ("RADIAL", 5),
    4: ("OPENCV", 8),
}


_COLMAP_PARAM_COUNTS = dict(_COLMAP_MODELS.values())


@dataclass(frozen=True)
class _ColmapIntrinsics:
    """One COLMAP camera reduced to a pinhole; ``distorted`` if any distortion term is non-zero."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    distorted: bool


def load_colmap(path: str | os.PathLike) -> list[Camera]:
    """Cameras of a COLMAP sparse model (text or binary), sorted by image name.

    ``path`` is the model folder or a scene folder holding ``sparse/0`` or ``sparse``. COLMAP
    poses are world->camera in the OpenCV frame and pixel centres at +0.5, as here. Lens
    distortion is ignored (with one warning per call when any coefficient is non-zero).
    """
    folder, ext = _colmap_folder(path)
    intrinsics = _read_colmap_cameras(folder / f"cameras{ext}")
    images = _read_colmap_images(folder / f"images{ext}")
    if not images:
        raise CameraFileError(folder / f"images{ext}", "contains no images")
    cameras = []
    for image_id, qvec, tvec, camera_id, name in sorted(images, key=lambda im: im[4]):
        if camera_id not in intrinsics:
            raise CameraFileError(folder / f"images{ext}", f"image {image_id} uses unknown camera {camera_id}")
        cameras.append(_colmap_camera(folder / f"images{ext}", intrinsics[camera_id], qvec, tvec, name))
    if any(intrinsics[im[3]].distorted for im in images):
        warnings.warn(f"{folder}: COLMAP lens distortion is ignored (cameras treated as pinhole)", stacklevel=2)
    return cameras


def load_colmap_points(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """The sparse points of a COLMAP model: xyz (N,3) float32 and rgb (N,3) uint8."""
    folder, ext = _colmap_folder(path)
    points = folder / f"points3D{ext}"
    if not points.is_file():
        raise CameraFileError(points, "COLMAP points file not found")
    return _read_points_bin(points) if ext == ".bin" else _read_points_txt(points)


def _find_colmap_folder(path: str | os.PathLike) -> tuple[Path, str] | None:
    """The model folder and its extension (binary preferred) for a model or scene folder, if any."""
    base = Path(path)
    for folder in (base, base / "sparse" / "0", base / "sparse"):
        for ext in (".bin", ".txt"):
            if (folder / f"cameras{ext}").is_file() and (folder / f"images{ext}").is_file():
                return folder, ext
    return None


def _colmap_folder(path: str | os.PathLike) -> tuple[Path, str]:
    """Like :func:`_find_colmap_folder` but a missing model is a CameraFileError."""
    found = _find_colmap_folder(path)
    if found is None:
        raise CameraFileError(path, "no COLMAP model (cameras.bin/images.bin or cameras.txt/images.txt) found")
    return found


def _colmap_intrinsics(
    path: Path,
    model: str,
    width: float,
    height: float,
    params: Sequence[float],
) -> _ColmapIntrinsics:
    """Pinhole intrinsics from a COLMAP camera model's parameters."""
    if model not in _COLMAP_PARAM_COUNTS:
        raise CameraFileError(
            path, f"camera model {model} is not supported (supported: {', '.join(_COLMAP_PARAM_COUNTS)})"
        )
    n = _COLMAP_PARAM_COUNTS[model]
    if len(params) != n:
        raise CameraFileError(path, f"camera model {model} needs {n} parameters, got {len(params)}")
    if model in ("SIMPLE_PINHOLE", "SIMPLE_RADIAL", "RADIAL"):
        fx = fy = params[0]
        cx, cy, dist = params[1], params[2], params[3:]
    else:
        fx, fy, cx, cy, dist = params[0], params[1], params[2], params[3], params[4:]
    if width != int(width) or height != int(height) or width <= 0 or height <= 0:
        raise CameraFileError(path, f"invalid image size {width} x {height}")
    return _ColmapIntrinsics(int(width), int(height), fx, fy, cx, cy, any(d != 0 for d in dist))


def _colmap_camera(path: Path, intr: _ColmapIntrinsics, qvec: np.ndarray, tvec: np.ndarray, name: str) -> Camera:
    """A Camera from COLMAP intrinsics and a world->camera quaternion (w, x, y, z) + translation."""
    if not (np.all(np.isfinite(qvec)) and np.linalg.norm(qvec) > DEGENERATE_NORM):
        raise CameraFileError(path, f"image {name!r} has an invalid quaternion {qvec.tolist()}")
    viewmat = np.eye(4)
    viewmat[:3, :3] = quats_to_matrices(qvec)
    viewmat[:3, 3] = tvec
    try:
        return Camera(viewmat, intr.fx, intr.fy, intr.cx, intr.cy, intr.width, intr.height, name)
    except ValueError as exc:
        raise CameraFileError(path, f"image {name!r}: {exc}") from exc


# -- text --------------------------------------------------------------------------------------------
def _text_lines(path: Path) -> list[tuple[int, str]]:
    """(line number, stripped line) of a COLMAP text file without comments; empty lines are kept
    because in images.txt an empty line is an image without 2D points."""
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, ValueError) as exc:
        raise CameraFileError(path, f"cannot read: {exc}") from exc
    return [(no, line.strip()) for no, line in enumerate(text.splitlines(), 1) if not line.lstrip().startswith("#")]


def _parse_numbers(path: Path, line_no: int, fields: Sequence[str], kind: Callable[[str], Any] = float) -> list:
    """Fields converted by ``kind``; a bad or non-finite field is a CameraFileError naming the line."""
    try:
        values = [kind(f) for f in fields]
    except ValueError as exc:
        raise CameraFileError(path, f"line {line_no}: {exc}") from exc
    if not all(math.isfinite(v) for v in values):
        raise CameraFileError(path, f"line {line_no}: non-finite value")
    return values


def _read_colmap_cameras(path: Path) -> dict[int, _ColmapIntrinsics]:
    """cameras.txt / cameras.bin -> intrinsics by camera id."""
    if path.suffix == ".bin":
        return _read_cameras_bin(path)
    cameras = {}
    for line_no, line in _text_lines(path):
        fields = line.split()
        if not fields:
            continue
        if len(fields) < 4:
            raise CameraFileError(path, f"line {line_no}: expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS...")
        (camera_id,) = _parse_numbers(path, line_no, fields[:1], int)
        width, height, *params = _parse_numbers(path, line_no, fields[2:])
        cameras[camera_id] = _colmap_intrinsics(path, fields[1], width, height, params)
    return cameras


def _read_colmap_images(path: Path) -> list[tuple[int, np.ndarray, np.ndarray, int, str]]:
    """images.txt / images.bin -> (image id, qvec, tvec, camera id, name) per image."""
    if path.suffix == ".bin":
        return _read_images_bin(path)
    lines = _text_lines(path)
    images, i = [], 0
    while i < len(lines):
        line_no, line = lines[i]
        if not line:
            i += 1
            continue
        fields = line.split(maxsplit=9)
        if len(fields) != 10:
            raise CameraFileError(path, f"line {line_no}: expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME")
        image_id, camera_id = _parse_numbers(path, line_no, [fields[0], fields[8]], int)
        numbers = np.array(_parse_numbers(path, line_no, fields[1:8]))
        images.append((image_id, numbers[:4], numbers[4:], camera_id, fields[9]))
        i += 2  # the next line lists the image's 2D points (possibly empty)
    return images


def _read_points_txt(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """points3D.txt -> xyz float32 (N,3), rgb uint8 (N,3)."""
    xyz, rgb = [], []
    for line_no, line in _text_lines(path):
        fields = line.split()
        if not fields:
            continue
        if len(fields) < 8 or len(fields) % 2:
            raise CameraFileError(path, f"line {line_no}: expected POINT3D_ID X Y Z R G B ERROR TRACK...")
        xyz.append(_parse_numbers(path, line_no, fields[1:4]))
        rgb.append(_parse_numbers(path, line_no, fields[4:7], int))
    return _points_arrays(path, xyz, rgb)


def _points_arrays(path: Path, xyz: list, rgb: list) -> tuple[np.ndarray, np.ndarray]:
    """Stack point lists into (N,3) float32 / uint8 arrays, checking colours fit in a byte."""
    xyz_arr = np.array(xyz, dtype=np.float32).reshape(-1, 3)
    rgb_arr = np.array(rgb, dtype=np.int64).reshape(-1, 3)
    if rgb_arr.size and (rgb_arr.min() < 0 or rgb_arr.max() > 255):
        raise CameraFileError(path, "point colours must be in 0..255")
    return xyz_arr, rgb_arr.astype(np.uint8)


# -- binary ------------------------------------------------------------------------------------------
class _BinaryReader:
    """Sequential little-endian reads from a file's bytes; running out is a CameraFileError."""

    def __init__(self, path: Path) -> None:
        self.path = path
        try:
            self.data = path.read_bytes()
        except OSError as exc:
            raise CameraFileError(path, f"cannot read: {exc}") from exc
        self.offset = 0

    def read(self, fmt: str) -> tuple:
        size = struct.calcsize("<" + fmt)
        self.skip(size)
        return struct.unpack_from("<" + fmt, self.data, self.offset - size)

    def skip(self, size: int) -> None:
        if size < 0 or self.offset + size > len(self.data):
            raise CameraFileError(
                self.path, f"truncated: needs {size} more bytes at byte {self.offset} of {len(self.data)}"
            )
        self.offset += size

    def read_cstring(self) -> str:
        end = self.data.find(b"\0", self.offset)
        if end < 0:
            raise CameraFileError(self.path, f"truncated: unterminated image name at byte {self.offset}")
        raw, self.offset = self.data[self.offset : end], end + 1
        try:
            return raw.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise CameraFileError(self.path, f"image name is not UTF-8 at byte {self.offset}") from exc

    def finish(self) -> None:
        if self.offset != len(self.data):
            raise CameraFileError(self.path, f"{len(self.data) - self.offset} unexpected trailing bytes")

    def finite(self, values: tuple, what: str) -> tuple:
        if not all(math.isfinite(v) for v in values):
            raise CameraFileError(self.path, f"non-finite {what} before byte {self.offset}")
        return values


def _read_cameras_bin(path: Path) -> dict[int, _ColmapIntrinsics]:
    """cameras.bin: uint64 count; per camera int32 id, int32 model, uint64 w, uint64 h, float64 params."""
    reader, cameras = _BinaryReader(path), {}
    (count,) = reader.read("Q")
    for _ in range(count):
        camera_id, model_id, width, height = reader.read("iiQQ")
        if model_id not in _COLMAP_MODELS:
            raise CameraFileError(
                path,
                f"camera {camera_id} has unsupported model id {model_id} "
                f"(supported: {', '.join(_COLMAP_PARAM_COUNTS)})",
            )
        model, n = _COLMAP_MODELS[model_id]
        params = reader.finite(reader.read(f"{n}d"), "camera parameters")
        cameras[camera_id] = _colmap_intrinsics(path, model, width, height, params)
    reader.finish()
    return cameras


def _read_images_bin(path: Path) -> list[tuple[int, np.ndarray, np.ndarray, int, str]]:
    """images.bin: uint64 count; per image int32 id, 4+3 float64, int32 camera, name\\0, 2D points."""
    reader, images = _BinaryReader(path), []
    (count,) = reader.read("Q")
    for _ in range(count):
        image_id, *numbers, camera_id = reader.read("i7di")
        reader.finite(tuple(numbers), "image pose")
        name = reader.read_cstring()
        (n_points,) = reader.read("Q")
        reader.skip(n_points * 24)  # float64 x, float64 y, int64 point3D id
        images.append((image_id, np.array(numbers[:4]), np.array(numbers[4:]), camera_id, name))
    reader.finish()
    return images


def _read_points_bin(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """points3D.bin: uint64 count; per point uint64 id, 3 float64, 3 uint8, float64 error, track."""
    reader, xyz, rgb = _BinaryReader(path), [], []
    (count,) = reader.read("Q")
    for _ in range(count):
        _, x, y, z, r, g, b, _, track_length = reader.read("Q3d3BdQ")
        xyz.append(reader.finite((x, y, z), "point position"))
        rgb.append((r, g, b))
        reader.skip(track_length * 8)  # int32 image id, int32 point2D index
    reader.finish()
    return _points_arrays(path, xyz, rgb)
