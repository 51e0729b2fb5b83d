"""Cameras and view sources: the pinhole camera type, pose-file loaders and generated view paths.

Every camera inside ``core`` uses the OpenCV frame (x right, y down, z forward), a world->camera
4x4 ``viewmat`` and pixel intrinsics with pixel centres at +0.5 (DESIGN.md section 3). Loaders convert
each file format to that frame at the edge and raise :class:`CameraFileError` on malformed input.
GT^2 visits views in order and warps matches from one view to the next, so the generators return
views ordered along their path (consecutive views are neighbours).
"""
from __future__ import annotations

import json
import math
import os
import struct
import tokenize
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
import torch

from .atomic import atomic_write
from .errors import CameraFileError
from .scene import GaussianScene

_ORTHO_TOL = 1e-4
MAX_IMAGE_SIDE = 65536
"""Largest image width or height a camera may have (Blender's limit): larger sizes in a camera file
are corruption, and rendering them would try to allocate terabytes."""
_IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")


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
        cls, R_c2w: np.ndarray, center: Sequence[float], fx: float, fy: float, cx: float, cy: float,
        width: int, height: int, name: str = "",
    ) -> "Camera":
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

    def scaled(self, factor: float) -> "Camera":
        """The same camera for an image resized by ``factor`` (e.g. 0.5, 0.25).

        Sizes are rounded; intrinsics scale by the actual per-axis size ratio, which equals
        ``factor`` when the size divides evenly and otherwise matches what an image resize does.
        """
        if not (math.isfinite(factor) and factor > 0):
            raise ValueError(f"scale factor must be positive, got {factor}")
        width = max(1, round(self.width * factor))
        height = max(1, round(self.height * factor))
        sx, sy = width / self.width, height / self.height
        return Camera(self.world_to_cam, self.fx * sx, self.fy * sy, self.cx * sx, self.cy * sy,
                      width, height, self.name)

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
    cameras: Sequence[Camera], device: torch.device | str | None = None, dtype: torch.dtype = torch.float32,
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


# ---------------------------------------------------------------------------------------------------
# 3DGS cameras.json
# ---------------------------------------------------------------------------------------------------
def load_cameras_json(path: str | os.PathLike) -> list[Camera]:
    """Cameras from the ``cameras.json`` written by the INRIA 3DGS trainer.

    Entries: ``position`` = camera centre (world), ``rotation`` = camera->world 3x3 (OpenCV axes,
    rows as lists), ``fx, fy, width, height``; the principal point is the image centre unless the
    optional ``cx, cy`` keys (written by :func:`save_cameras_json` for off-centre cameras) exist.
    """
    try:
        with open(path, encoding="utf-8") as f:
            data = json.load(f)
    except (OSError, ValueError) as exc:
        raise CameraFileError(path, f"cannot read cameras.json: {exc}") from exc
    except RecursionError:
        raise CameraFileError(path, "cannot read cameras.json: its JSON is nested too deeply") from None
    if not isinstance(data, list) or not data:
        raise CameraFileError(path, "expected a non-empty JSON list of camera entries")
    return [_camera_from_json(path, i, entry) for i, entry in enumerate(data)]


def _camera_from_json(path: str | os.PathLike, index: int, entry: Any) -> Camera:
    """One cameras.json entry -> Camera; any problem becomes a CameraFileError naming the entry."""
    where = f"camera entry {index}"
    if not isinstance(entry, dict):
        raise CameraFileError(path, f"{where} is not a JSON object")
    missing = [k for k in ("width", "height", "position", "rotation", "fx", "fy") if k not in entry]
    if missing:
        raise CameraFileError(path, f"{where} lacks key(s) {', '.join(missing)}")
    width, height = _json_number(path, where, entry, "width"), _json_number(path, where, entry, "height")
    position = _json_array(path, where, entry, "position", (3,))
    rotation = _json_array(path, where, entry, "rotation", (3, 3))
    cx = _json_number(path, where, entry, "cx") if "cx" in entry else width / 2.0
    cy = _json_number(path, where, entry, "cy") if "cy" in entry else height / 2.0
    name = entry.get("img_name", entry.get("id", ""))
    try:
        return Camera.from_cam_to_world(
            rotation, position, _json_number(path, where, entry, "fx"), _json_number(path, where, entry, "fy"),
            cx, cy, width, height, str(name),
        )
    except ValueError as exc:
        raise CameraFileError(path, f"{where}: {exc}") from exc


def _json_number(path: str | os.PathLike, where: str, entry: dict, key: str) -> float:
    """A finite JSON number (not a bool or string) from ``entry[key]``."""
    value = entry[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(_as_float(value)):
        raise CameraFileError(path, f"{where}: {key} must be a finite number, got {_short(value)}")
    return value


def _as_float(value: float) -> float:
    """``value`` as a float; integers beyond the float range (JSON allows them) become Inf."""
    try:
        return float(value)
    except OverflowError:
        return math.inf


def _short(value: Any, limit: int = 60) -> str:
    """repr of a JSON value, cut to ``limit`` characters for a one-line message."""
    text = repr(value)
    return text if len(text) <= limit else text[:limit] + "..."


def _json_array(path: str | os.PathLike, where: str, entry: dict, key: str, shape: tuple[int, ...]) -> np.ndarray:
    """A finite float array of the given shape from nested JSON lists."""
    value = entry[key]
    try:
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        arr = None
    except OverflowError:  # an integer beyond the float range
        arr = None
    if arr is None or arr.shape != shape or _has_bool(value):
        raise CameraFileError(path, f"{where}: {key} must be numbers of shape {shape}, got {_short(value)}")
    if not np.all(np.isfinite(arr)):
        raise CameraFileError(path, f"{where}: {key} contains non-finite values")
    return arr


def _has_bool(value: Any) -> bool:
    """True if a nested JSON list holds a boolean (numpy would silently read it as 0/1)."""
    if isinstance(value, list):
        return any(_has_bool(v) for v in value)
    return isinstance(value, bool)


def save_cameras_json(path: str | os.PathLike, cameras: Sequence[Camera]) -> None:
    """Write cameras in the INRIA ``cameras.json`` layout, atomically (temp file + os.replace).

    ``cx, cy`` are added only for cameras whose principal point is off the image centre, so
    ordinary cameras produce exactly the trainer's layout and every camera round-trips.
    """
    if not cameras:
        raise ValueError("save_cameras_json needs at least one camera")
    entries = []
    for i, cam in enumerate(cameras):
        c2w = cam.cam_to_world
        entry: dict[str, Any] = {
            "id": i, "img_name": cam.name, "width": cam.width, "height": cam.height,
            "position": c2w[:3, 3].tolist(), "rotation": c2w[:3, :3].tolist(), "fy": cam.fy, "fx": cam.fx,
        }
        if cam.cx != cam.width / 2.0 or cam.cy != cam.height / 2.0:
            entry.update(cx=cam.cx, cy=cam.cy)
        entries.append(entry)
    _write_atomically(path, json.dumps(entries, indent=1))


def _write_atomically(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` atomically, reporting OS failures as a CameraFileError naming the file."""
    try:
        atomic_write(path, text)
    except OSError as exc:
        raise CameraFileError(path, f"cannot write: {exc}") from exc


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
            read_header = np.lib.format.read_array_header_1_0 if version == (1, 0) \
                else np.lib.format.read_array_header_2_0
            shape, _, dtype = read_header(f)
            data_bytes = os.fstat(f.fileno()).st_size - f.tell()
        if len(shape) != 2 or shape[0] == 0 or shape[1] != 17:
            raise ValueError(f"expected an N x 17 array (3x5 pose + near, far), got shape {shape}")
        if dtype.kind not in "iuf":
            raise ValueError(f"expected real numbers, got dtype {dtype}")
        if shape[0] * shape[1] * dtype.itemsize > data_bytes:
            raise ValueError(f"truncated: the header promises a {shape[0]} x 17 array but only {data_bytes} "
                             "bytes of data follow")
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
        return Camera.from_cam_to_world(R_c2w, pose[:, 3], f * sx, f * sy, width / 2.0, height / 2.0,
                                        width, height, f"{index:03d}")
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


# ---------------------------------------------------------------------------------------------------
# COLMAP sparse models
# ---------------------------------------------------------------------------------------------------
# model id -> (name, parameter count); the supported pinhole-like models (distortion ignored).
_COLMAP_MODELS = {0: ("SIMPLE_PINHOLE", 3), 1: ("PINHOLE", 4), 2: ("SIMPLE_RADIAL", 4), 3: ("RADIAL", 5),
                  4: ("OPENCV", 8)}
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
    path: Path, model: str, width: float, height: float, params: Sequence[float],
) -> _ColmapIntrinsics:
    """Pinhole intrinsics from a COLMAP camera model's parameters."""
    if model not in _COLMAP_PARAM_COUNTS:
        raise CameraFileError(path, f"camera model {model} is not supported "
                                    f"(supported: {', '.join(_COLMAP_PARAM_COUNTS)})")
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
    norm = np.linalg.norm(qvec)
    if not (np.all(np.isfinite(qvec)) and norm > 1e-12):
        raise CameraFileError(path, f"image {name!r} has an invalid quaternion {qvec.tolist()}")
    viewmat = np.eye(4)
    viewmat[:3, :3] = _quat_to_rotmat(qvec / norm)
    viewmat[:3, 3] = tvec
    try:
        return Camera(viewmat, intr.fx, intr.fy, intr.cx, intr.cy, intr.width, intr.height, name)
    except ValueError as exc:
        raise CameraFileError(path, f"image {name!r}: {exc}") from exc


def _quat_to_rotmat(q: np.ndarray) -> np.ndarray:
    """Rotation matrix of a unit quaternion (w, x, y, z)."""
    w, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


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
            raise CameraFileError(self.path, f"truncated: needs {size} more bytes at byte {self.offset} "
                                             f"of {len(self.data)}")
        self.offset += size

    def read_cstring(self) -> str:
        end = self.data.find(b"\0", self.offset)
        if end < 0:
            raise CameraFileError(self.path, f"truncated: unterminated image name at byte {self.offset}")
        raw, self.offset = self.data[self.offset:end], end + 1
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
            raise CameraFileError(path, f"camera {camera_id} has unsupported model id {model_id} "
                                        f"(supported: {', '.join(_COLMAP_PARAM_COUNTS)})")
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


# ---------------------------------------------------------------------------------------------------
# Dispatch
# ---------------------------------------------------------------------------------------------------
def load_views(path: str | os.PathLike) -> list[Camera]:
    """Cameras from whatever ``path`` is: a cameras.json, a poses_bounds.npy, a COLMAP model
    folder (or its files), or a scene folder holding one of them (looked for in that order).
    LLFF cameras come at the file's full resolution."""
    p = Path(path)
    if not p.exists():
        raise CameraFileError(path, "does not exist")
    if p.is_file():
        if p.suffix.lower() == ".json":
            return load_cameras_json(p)
        if p.suffix.lower() == ".npy":
            return load_llff(p).cameras
        if p.stem in ("cameras", "images", "points3D") and p.suffix in (".bin", ".txt"):
            return load_colmap(p.parent)
        raise CameraFileError(path, "not a camera file (expected cameras.json, poses_bounds.npy or a COLMAP model)")
    if (p / "cameras.json").is_file():
        return load_cameras_json(p / "cameras.json")
    if _find_colmap_folder(p) is not None:
        return load_colmap(p)
    if (p / "poses_bounds.npy").is_file():
        return load_llff(p).cameras
    raise CameraFileError(path, "no cameras found: expected cameras.json, poses_bounds.npy, "
                                "or a COLMAP model (here, in sparse/0 or in sparse)")


# ---------------------------------------------------------------------------------------------------
# Generated views
# ---------------------------------------------------------------------------------------------------
def look_at(
    eye: Sequence[float], target: Sequence[float], *, width: int, height: int, fov_deg: float = 50.0,
    up: Sequence[float] = (0.0, 0.0, 1.0), name: str = "",
) -> Camera:
    """A camera at ``eye`` looking at ``target`` with ``up`` pointing up in the image.

    ``fov_deg`` is the horizontal field of view; pixels are square and the principal point centred.
    """
    if not 0.0 < fov_deg < 180.0:
        raise ValueError(f"fov_deg must be in (0, 180), got {fov_deg}")
    eye_v, target_v = np.asarray(eye, dtype=np.float64), np.asarray(target, dtype=np.float64)
    forward = _unit(target_v - eye_v, "look direction")
    right = np.cross(forward, _unit(up, "up"))
    if np.linalg.norm(right) < 1e-6:
        raise ValueError("look_at: the view direction is parallel to the up vector")
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    f = (width / 2.0) / math.tan(math.radians(fov_deg) / 2.0)
    return Camera.from_cam_to_world(np.stack([right, down, forward], axis=1), eye_v, f, f,
                                    width / 2.0, height / 2.0, width, height, name)


def camera_path(cameras: Sequence[Camera], frames_per_gap: int, *, closed: bool = False) -> list[Camera]:
    """A smooth path through ``cameras`` in their order, as a rendered video would go: ``frames_per_gap``
    frames from each camera to the next (the camera itself first), rotation by slerp, centre linear,
    intrinsics and size of the gap's first camera; ``closed`` adds the gap from the last back to the first,
    else the last camera ends the path. Consecutive cameras must turn by less than 180 degrees."""
    if frames_per_gap < 1 or not cameras:
        raise ValueError(f"need cameras and frames_per_gap >= 1, got {len(cameras)} and {frames_per_gap}")
    gaps = len(cameras) if closed and len(cameras) > 1 else len(cameras) - 1
    path = []
    for i in range(gaps):
        a, b = cameras[i], cameras[(i + 1) % len(cameras)]
        r_a = a.cam_to_world[:3, :3]
        axis_angle = _rotation_log(r_a.T @ b.cam_to_world[:3, :3])
        for k in range(frames_per_gap):
            t = k / frames_per_gap
            path.append(Camera.from_cam_to_world(r_a @ _rotation_exp(t * axis_angle), (1 - t) * a.center + t * b.center,
                                                 a.fx, a.fy, a.cx, a.cy, a.width, a.height, f"{a.name}+{k}"))
    return path if closed and len(cameras) > 1 else path + [cameras[-1]]


def _rotation_log(r: np.ndarray) -> np.ndarray:
    """Axis times angle (radians) of a rotation matrix with angle below 180 degrees."""
    angle = math.acos(min(1.0, max(-1.0, (np.trace(r) - 1.0) / 2.0)))
    if angle > math.pi - 1e-6:
        raise ValueError("consecutive cameras turn by 180 degrees: the path between them is ambiguous")
    skew = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]]) / 2.0
    return skew if angle < 1e-12 else skew * angle / math.sin(angle)


def _rotation_exp(w: np.ndarray) -> np.ndarray:
    """Rotation matrix of axis times angle ``w`` (Rodrigues)."""
    angle = float(np.linalg.norm(w))
    k = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    if angle < 1e-12:
        return np.eye(3) + k
    k /= angle
    return np.eye(3) + math.sin(angle) * k + (1.0 - math.cos(angle)) * (k @ k)


def orbit_views(
    center: Sequence[float], radius: float, n: int, *, width: int, height: int, fov_deg: float = 50.0,
    elevation_deg: float = 20.0, up: Sequence[float] = (0.0, 0.0, 1.0), front: Sequence[float] = (0.0, -1.0, 0.0),
) -> list[Camera]:
    """``n`` cameras on a ring around ``center`` looking at it, ordered by azimuth.

    The ring lies ``elevation_deg`` above the plane normal to ``up``; the first camera sits on the
    ``front`` side (Blender's front view by default: on -y, looking along +y) and azimuth increases
    counter-clockwise seen from ``up``.
    """
    azimuths = np.linspace(0.0, 360.0, n, endpoint=False)
    return _ring_views(center, radius, azimuths, elevation_deg, up, front, width, height, fov_deg, "orbit")


def arc_views(
    center: Sequence[float], radius: float, n: int, *, width: int, height: int, fov_deg: float = 50.0,
    arc_deg: float = 60.0, elevation_deg: float = 10.0, up: Sequence[float] = (0.0, 0.0, 1.0),
    front: Sequence[float] = (0.0, -1.0, 0.0),
) -> list[Camera]:
    """``n`` cameras on an arc of ``arc_deg`` degrees on the ``front`` side of ``center``, looking at
    it and ordered along the arc: forward-facing views for front-facing scenes (like LLFF)."""
    if not 0.0 <= arc_deg < 360.0:
        raise ValueError(f"arc_deg must be in [0, 360), got {arc_deg}")
    azimuths = np.linspace(-arc_deg / 2.0, arc_deg / 2.0, n) if n > 1 else np.zeros(n)
    return _ring_views(center, radius, azimuths, elevation_deg, up, front, width, height, fov_deg, "arc")


def _ring_views(
    center: Sequence[float], radius: float, azimuths_deg: np.ndarray, elevation_deg: float,
    up: Sequence[float], front: Sequence[float], width: int, height: int, fov_deg: float, prefix: str,
) -> list[Camera]:
    """Cameras at the given azimuths (0 = ``front``) and elevation on a sphere around ``center``."""
    if len(azimuths_deg) < 1:
        raise ValueError("at least one view is needed")
    if not (math.isfinite(radius) and radius > 0):
        raise ValueError(f"radius must be positive, got {radius}")
    if not -90.0 < elevation_deg < 90.0:
        raise ValueError(f"elevation_deg must be in (-90, 90), got {elevation_deg}")
    up_v = _unit(up, "up")
    e1 = _horizontal_direction(front, up_v)
    e2 = np.cross(up_v, e1)
    c = np.asarray(center, dtype=np.float64)
    el = math.radians(elevation_deg)
    cameras = []
    for i, az in enumerate(np.radians(azimuths_deg)):
        offset = math.cos(el) * (math.cos(az) * e1 + math.sin(az) * e2) + math.sin(el) * up_v
        cameras.append(look_at(c + radius * offset, c, width=width, height=height, fov_deg=fov_deg,
                               up=up_v, name=f"{prefix}_{i:03d}"))
    return cameras


def _horizontal_direction(front: Sequence[float], up: np.ndarray) -> np.ndarray:
    """``front`` projected onto the plane normal to ``up``; if they are parallel, the world axis
    least aligned with ``up`` (never parallel to it) projected instead."""
    direction = np.asarray(front, dtype=np.float64)
    flat = direction - (direction @ up) * up
    if np.linalg.norm(flat) < 1e-6:
        axis = np.eye(3)[np.argmin(np.abs(up))]
        flat = axis - (axis @ up) * up
    return flat / np.linalg.norm(flat)


def _unit(v: Sequence[float], what: str) -> np.ndarray:
    """``v`` normalised; ValueError if it is zero or not finite."""
    arr = np.asarray(v, dtype=np.float64)
    norm = np.linalg.norm(arr)
    if arr.shape != (3,) or not math.isfinite(norm) or norm < 1e-12:
        raise ValueError(f"{what} must be a finite non-zero 3-vector, got {arr.tolist()}")
    return arr / norm


def estimate_up_axis(
    points: np.ndarray, prefer: Sequence[float] = (0.0, 0.0, 1.0), flatness: float = 0.5,
) -> np.ndarray:
    """The scene's up axis: the smallest-variance principal axis of ``points``.

    Reliable for flat-ish scenes (ground planes, tabletop objects, a donut's symmetry axis); when
    the smallest variance is not below ``flatness`` times the middle one no axis stands out and
    ``prefer`` is returned. The sign is chosen to agree with ``prefer``.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    prefer_v = _unit(prefer, "prefer")
    if len(pts) < 3:
        return prefer_v
    variances, axes = np.linalg.eigh(np.cov(pts.T))
    if not variances[0] < flatness * variances[1]:
        return prefer_v
    axis = axes[:, 0]
    return axis if axis @ prefer_v >= 0 else -axis


def auto_views(
    scene: GaussianScene, n: int, *, width: int = 256, height: int = 256, kind: str = "auto",
    fov_deg: float = 50.0, elevation_deg: float = 20.0, up: Sequence[float] | str = (0.0, 0.0, 1.0),
    quantile: float = 0.98, margin: float = 1.1,
) -> list[Camera]:
    """Ordered views fitted to a scene when no cameras are given.

    The Gaussians' robust bounds (``scene.bounds(quantile)``, ignoring floaters) give a box; the
    camera distance is the smallest at which all eight box corners project inside every image,
    times ``margin`` (1 = corners may touch the border). A box, not its bounding sphere, so flat or
    long objects fill the frame. ``kind``: "orbit" (a full ring), "arc" (a 60 degree
    forward-facing arc on the -y side, Blender's front) or "auto" (= orbit: a lone object has no
    known front). ``up`` is a vector (world +z, Blender's convention, by default) or "auto" for
    :func:`estimate_up_axis`.
    """
    if kind not in ("auto", "orbit", "arc"):
        raise ValueError(f"kind must be 'auto', 'orbit' or 'arc', got {kind!r}")
    if margin <= 0:
        raise ValueError(f"margin must be positive, got {margin}")
    lo, hi = (b.detach().double().cpu().numpy() for b in scene.bounds(quantile))
    center = (lo + hi) / 2.0
    sphere_radius = max(float(np.linalg.norm(hi - lo)) / 2.0, 1e-6)
    if isinstance(up, str):
        if up != "auto":
            raise ValueError(f"up must be a 3-vector or 'auto', got {up!r}")
        means = scene.means.detach().double().cpu().numpy()
        up = estimate_up_axis(means[np.all((means >= lo) & (means <= hi), axis=1)])
    fov_x = math.radians(fov_deg)
    fov_y = 2.0 * math.atan(math.tan(fov_x / 2.0) * height / width)
    make = arc_views if kind == "arc" else orbit_views

    def views(radius: float) -> list[Camera]:
        return make(center, radius, n, width=width, height=height, fov_deg=fov_deg,
                    elevation_deg=elevation_deg, up=up)

    corners = np.array([[(lo, hi)[(i >> a) & 1][a] for a in range(3)] for i in range(8)])
    enclosing = sphere_radius / math.sin(min(fov_x, fov_y) / 2.0)  # the sphere fits: so does the box
    return views(_fitting_radius(views, corners, sphere_radius, enclosing) * margin)


def _fitting_radius(views: Callable[[float], list[Camera]], corners: np.ndarray, low: float, high: float) -> float:
    """Smallest orbit radius in [low, high] at which every corner projects inside every view (bisection)."""
    def inside(radius: float) -> bool:
        for cam in views(radius):
            uv, depth = cam.project(corners)
            if np.any(depth <= 0) or np.any(uv < 0) or np.any(uv > [cam.width, cam.height]):
                return False
        return True

    for _ in range(30):
        mid = 0.5 * (low + high)
        low, high = (low, mid) if inside(mid) else (mid, high)
    return high
