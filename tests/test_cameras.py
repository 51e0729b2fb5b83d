"""Tests for core.cameras: the Camera type, pose-file loaders and generated view paths.

Real data (fern LLFF poses, the garden cameras, the donut scene) comes from ../shared and is
skipped with a reason when absent; COLMAP fixtures are written here by a tiny writer that follows
COLMAP's documented text and binary layouts.
"""

from __future__ import annotations

import json
import math
import struct
import warnings
from pathlib import Path

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from gt2gs_blender.core.cameras.camera import Camera, stack_cameras
from gt2gs_blender.core.cameras.cameras_json import load_cameras_json, save_cameras_json
from gt2gs_blender.core.cameras.colmap import load_colmap, load_colmap_points
from gt2gs_blender.core.cameras.files import load_views
from gt2gs_blender.core.cameras.generate import auto_views
from gt2gs_blender.core.cameras.llff import LLFFData, load_llff
from gt2gs_blender.core.cameras.poses import arc_views, camera_path, look_at, orbit_views
from gt2gs_blender.core.cameras.up import estimate_up_axis
from gt2gs_blender.core.errors import CameraFileError
from gt2gs_blender.core.render import render
from gt2gs_blender.core.scene.gaussians import GaussianScene

SHARED = Path(__file__).resolve().parents[1].parent / "shared"
FERN = SHARED / "data" / "scenes" / "fern_llff"
GARDEN = SHARED / "data" / "scenes" / "garden_points" / "test_garden.npz"
DONUT = SHARED / "data" / "scenes" / "donut" / "point_cloud.ply"


def require(path: Path) -> Path:
    """Skip the test (with the path as reason) when shared data is missing."""
    if not path.exists():
        pytest.skip(f"shared test data missing: {path}")
    return path


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A uniformly random proper rotation."""
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def random_camera(rng: np.random.Generator, name: str = "", centred: bool = True) -> Camera:
    width, height = int(rng.integers(50, 900)), int(rng.integers(50, 900))
    cx, cy = (width / 2, height / 2) if centred else (rng.uniform(0, width), rng.uniform(0, height))
    return Camera.from_cam_to_world(
        random_rotation(rng),
        rng.normal(size=3) * 5,
        rng.uniform(100, 1000),
        rng.uniform(100, 1000),
        cx,
        cy,
        width,
        height,
        name,
    )


def assert_same_camera(a: Camera, b: Camera, atol: float = 1e-12) -> None:
    np.testing.assert_allclose(a.world_to_cam, b.world_to_cam, rtol=0, atol=atol)
    np.testing.assert_allclose(a.K, b.K, rtol=1e-12, atol=0)
    assert (a.width, a.height, a.name) == (b.width, b.height, b.name)


# ---------------------------------------------------------------------------------------------------
# Camera
# ---------------------------------------------------------------------------------------------------
def test_project_known_points() -> None:
    cam = Camera(np.eye(4), fx=100, fy=120, cx=64, cy=48, width=128, height=96)
    uv, depth = cam.project(np.array([[1.0, 2.0, 10.0], [0.0, 0.0, 3.0]]))
    np.testing.assert_allclose(uv, [[74.0, 72.0], [64.0, 48.0]])
    np.testing.assert_allclose(depth, [10.0, 3.0])

    # At (5, 0, 0) looking along -x with image-down = world -z: right = down x forward = +y.
    R_c2w = np.array([[0.0, 0.0, -1.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])  # columns right, down, forward
    cam = Camera.from_cam_to_world(R_c2w, [5.0, 0.0, 0.0], 100, 100, 64, 48, 128, 96)
    uv, depth = cam.project([[0.0, 1.0, 0.0], [0.0, 0.0, 2.0], [10.0, 0.0, 0.0]])
    np.testing.assert_allclose(uv[:2], [[84.0, 48.0], [64.0, 8.0]])
    np.testing.assert_allclose(depth, [5.0, 5.0, -5.0])
    np.testing.assert_allclose(cam.forward, [-1.0, 0.0, 0.0])
    np.testing.assert_allclose(cam.center, [5.0, 0.0, 0.0])


def test_pixel_centres_at_half() -> None:
    """A ray through the centre of pixel (row i, col j) lands at (j + 0.5, i + 0.5)."""
    cam = Camera(np.eye(4), fx=50, fy=50, cx=16, cy=8, width=32, height=16)
    i, j = 3, 7
    ray = np.linalg.solve(cam.K, [j + 0.5, i + 0.5, 1.0])
    uv, _ = cam.project(ray * 4.0)
    np.testing.assert_allclose(uv, [[j + 0.5, i + 0.5]])
    assert math.isclose(Camera(np.eye(4), 16, 16, 16, 16, 32, 32).fov_x, math.pi / 2)


def test_scaled_resizes_image_coordinates() -> None:
    rng = np.random.default_rng(0)
    cam = Camera.from_cam_to_world(random_rotation(rng), [0, 0, 0], 300, 310, 320.5, 240.25, 640, 480)
    points = cam.cam_to_world[:3, :3] @ np.array([[0.3, -0.2, 4.0], [-1.0, 0.5, 9.0]]).T
    uv, _ = cam.project(points.T)
    for factor in (0.5, 0.25):
        small = cam.scaled(factor)
        assert (small.width, small.height) == (640 * factor, 480 * factor)
        np.testing.assert_allclose(
            [small.fx, small.fy, small.cx, small.cy], np.array([300, 310, 320.5, 240.25]) * factor
        )
        np.testing.assert_allclose(small.project(points.T)[0], uv * factor)
        np.testing.assert_array_equal(small.world_to_cam, cam.world_to_cam)
    odd = Camera(np.eye(4), 100, 100, 50.5, 30.5, 101, 61).scaled(0.5)
    assert (odd.width, odd.height) == (round(50.5), round(30.5))
    assert math.isclose(odd.fx / 100, odd.width / 101) and math.isclose(odd.fy / 100, odd.height / 61)
    with pytest.raises(ValueError, match="positive"):
        cam.scaled(0)


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_cam_to_world_is_the_inverse(seed: int) -> None:
    rng = np.random.default_rng(seed)
    R, c = random_rotation(rng), rng.normal(size=3) * 10
    cam = Camera.from_cam_to_world(R, c, 200, 200, 100, 100, 200, 200)
    np.testing.assert_allclose(cam.cam_to_world @ cam.world_to_cam, np.eye(4), atol=1e-12)
    np.testing.assert_allclose(cam.center, c, atol=1e-12)
    np.testing.assert_allclose(cam.forward, R[:, 2], atol=1e-15)
    _, depth = cam.project(np.stack([c, c + 2.0 * R[:, 2]]))
    np.testing.assert_allclose(depth, [0.0, 2.0], atol=1e-12)


def test_camera_is_immutable() -> None:
    cam = Camera(np.eye(4), 10, 10, 5, 5, 10, 10)
    with pytest.raises(ValueError):
        cam.world_to_cam[0, 3] = 1.0
    with pytest.raises(AttributeError):
        cam.fx = 3.0  # type: ignore[misc]


def _bad_viewmat(kind: str) -> np.ndarray:
    m = np.eye(4)
    if kind == "scaled":
        m[:3, :3] *= 1.01
    elif kind == "reflection":
        m[0, 0] = -1.0
    elif kind == "nan":
        m[1, 3] = np.nan
    elif kind == "last_row":
        m[3, 0] = 0.5
    return m


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(world_to_cam=_bad_viewmat("scaled")), "orthonormal"),
        (dict(world_to_cam=_bad_viewmat("reflection")), "reflection"),
        (dict(world_to_cam=_bad_viewmat("nan")), "non-finite"),
        (dict(world_to_cam=_bad_viewmat("last_row")), "last row"),
        (dict(world_to_cam=np.eye(3)), "4x4"),
        (dict(world_to_cam="eye"), "4x4"),
        (dict(fx=0.0), "positive"),
        (dict(fy=-1.0), "positive"),
        (dict(cx=float("inf")), "finite"),
        (dict(cy=None), "finite"),
        (dict(width=0), "width"),
        (dict(height=10.5), "height"),
        (dict(width=True), "width"),
    ],
)
def test_camera_validation(kwargs: dict, match: str) -> None:
    args = dict(world_to_cam=np.eye(4), fx=10.0, fy=10.0, cx=5.0, cy=5.0, width=10, height=10) | kwargs
    with pytest.raises(ValueError, match=match):
        Camera(**args)


def test_stack_cameras() -> None:
    rng = np.random.default_rng(1)
    cams = [
        Camera.from_cam_to_world(random_rotation(rng), rng.normal(size=3), 50, 60, 32, 24, 64, 48) for _ in range(3)
    ]
    viewmats, Ks, width, height = stack_cameras(cams, dtype=torch.float64)
    assert viewmats.shape == (3, 4, 4) and Ks.shape == (3, 3, 3) and (width, height) == (64, 48)
    assert viewmats.dtype == torch.float64
    np.testing.assert_array_equal(viewmats[1].numpy(), cams[1].world_to_cam)
    np.testing.assert_array_equal(Ks[2].numpy(), cams[2].K)
    assert stack_cameras(cams)[0].dtype == torch.float32
    with pytest.raises(ValueError, match="image size"):
        stack_cameras([*cams, cams[0].scaled(0.5)])
    with pytest.raises(ValueError, match="at least one"):
        stack_cameras([])


# ---------------------------------------------------------------------------------------------------
# cameras.json
# ---------------------------------------------------------------------------------------------------
def test_cameras_json_round_trip(tmp_path: Path) -> None:
    rng = np.random.default_rng(2)
    cams = [random_camera(rng, f"img_{i}.png", centred=i != 2) for i in range(4)]
    path = tmp_path / "cameras.json"
    save_cameras_json(path, cams)
    loaded = load_cameras_json(path)
    assert len(loaded) == len(cams)
    for a, b in zip(cams, loaded):
        assert_same_camera(a, b)
        np.testing.assert_allclose(a.center, b.center, rtol=0, atol=1e-12)
    entries = json.loads(path.read_text())
    assert set(entries[0]) == {"id", "img_name", "width", "height", "position", "rotation", "fy", "fx"}
    assert {"cx", "cy"} <= set(entries[2])
    np.testing.assert_array_equal(entries[1]["position"], cams[1].center)
    np.testing.assert_array_equal(entries[1]["rotation"], cams[1].cam_to_world[:3, :3])
    assert [p.name for p in tmp_path.iterdir()] == ["cameras.json"]  # no temp file left behind


def test_cameras_json_official_layout(tmp_path: Path) -> None:
    """An entry as the INRIA trainer writes it: centre, camera->world rotation rows, cx = w/2."""
    rotation = [[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]  # right -y, down -z, forward +x
    entry = {
        "id": 0,
        "img_name": "DSC0001",
        "width": 640,
        "height": 480,
        "position": [1.0, 2.0, 3.0],
        "rotation": rotation,
        "fy": 500.0,
        "fx": 510.0,
    }
    path = tmp_path / "cameras.json"
    path.write_text(json.dumps([entry]))
    (cam,) = load_cameras_json(path)
    np.testing.assert_allclose(cam.center, [1, 2, 3])
    np.testing.assert_allclose(cam.cam_to_world[:3, :3], rotation)
    np.testing.assert_allclose(cam.forward, np.array(rotation)[:, 2])
    assert (cam.fx, cam.fy, cam.cx, cam.cy, cam.name) == (510.0, 500.0, 320.0, 240.0, "DSC0001")


GOOD_ENTRY = {
    "id": 0,
    "img_name": "a",
    "width": 64,
    "height": 48,
    "position": [0.0, 0.0, 0.0],
    "rotation": np.eye(3).tolist(),
    "fy": 50.0,
    "fx": 50.0,
}


@pytest.mark.parametrize(
    "content, match",
    [
        ("{not json", "cannot read"),
        ("[]", "non-empty"),
        (json.dumps(GOOD_ENTRY), "non-empty JSON list"),
        (json.dumps([1, 2]), "not a JSON object"),
        (json.dumps([{k: v for k, v in GOOD_ENTRY.items() if k != "rotation"}]), "lacks key"),
        (json.dumps([GOOD_ENTRY | {"rotation": [[1, 0], [0, 1]]}]), "rotation"),
        (json.dumps([GOOD_ENTRY | {"rotation": [[1, 0, 0], [0, 1, 0], [0, 0]]}]), "rotation"),
        (json.dumps([GOOD_ENTRY | {"position": [0, "x", 0]}]), "position"),
        (json.dumps([GOOD_ENTRY | {"position": [0, True, 0]}]), "position"),
        (json.dumps([GOOD_ENTRY | {"position": [0, float("nan"), 0]}]), "non-finite"),
        (json.dumps([GOOD_ENTRY | {"fx": "50"}]), "fx"),
        (json.dumps([GOOD_ENTRY | {"width": 0}]), "width"),
        (json.dumps([GOOD_ENTRY | {"height": 47.5}]), "height"),
        (json.dumps([GOOD_ENTRY | {"rotation": (2 * np.eye(3)).tolist()}]), "orthonormal"),
        (json.dumps([GOOD_ENTRY, GOOD_ENTRY | {"fy": -3.0}]), "entry 1"),
    ],
)
def test_cameras_json_malformed(tmp_path: Path, content: str, match: str) -> None:
    path = tmp_path / "cameras.json"
    path.write_text(content)
    with pytest.raises(CameraFileError, match=match):
        load_cameras_json(path)


def test_cameras_json_unreadable(tmp_path: Path) -> None:
    with pytest.raises(CameraFileError, match="cannot read"):
        load_cameras_json(tmp_path / "missing.json")
    (tmp_path / "binary.json").write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(CameraFileError):
        load_cameras_json(tmp_path / "binary.json")
    with pytest.raises(ValueError, match="at least one"):
        save_cameras_json(tmp_path / "cameras.json", [])
    cams = [Camera(np.eye(4), 1, 1, 1, 1, 2, 2)]
    with pytest.raises(CameraFileError, match="cannot write"):
        save_cameras_json(tmp_path / "no_such_dir" / "cameras.json", cams)
    (tmp_path / "taken").mkdir()
    with pytest.raises(CameraFileError, match="cannot write"):
        save_cameras_json(tmp_path / "taken", cams)  # os.replace onto a folder fails
    assert sorted(p.name for p in tmp_path.iterdir()) == ["binary.json", "taken"]  # temp file removed


def garden_cameras() -> tuple[list[Camera], np.ndarray]:
    data = np.load(require(GARDEN))
    width, height = int(data["width"]), int(data["height"])
    cams = [
        Camera(v.astype(np.float64), K[0, 0], K[1, 1], K[0, 2], K[1, 2], width, height, f"garden_{i}")
        for i, (v, K) in enumerate(zip(data["viewmats"], data["Ks"]))
    ]
    return cams, data["means3d"]


def test_garden_cameras_json_round_trip(tmp_path: Path) -> None:
    cams, points = garden_cameras()
    path = tmp_path / "cameras.json"
    save_cameras_json(path, cams)
    loaded = load_cameras_json(path)
    data = np.load(GARDEN)
    viewmats, Ks, width, height = stack_cameras(loaded, dtype=torch.float64)
    np.testing.assert_allclose(viewmats.numpy(), data["viewmats"], rtol=0, atol=1e-6)
    np.testing.assert_allclose(Ks.numpy(), data["Ks"], rtol=0, atol=1e-4)
    assert (width, height) == (648, 420)
    for cam in loaded:
        uv, depth = cam.project(points)
        inside = (depth > 0) & (uv[:, 0] >= 0) & (uv[:, 0] < width) & (uv[:, 1] >= 0) & (uv[:, 1] < height)
        assert inside.mean() > 0.35, f"{cam.name}: only {inside.mean():.0%} of the garden in view"


# ---------------------------------------------------------------------------------------------------
# LLFF
# ---------------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def fern() -> tuple[LLFFData, np.ndarray]:
    poses = np.load(require(FERN / "poses_bounds.npy"))
    return load_llff(FERN, downscale=8), poses


def test_fern_poses_convert_to_opencv(fern: tuple[LLFFData, np.ndarray]) -> None:
    data, table = fern
    poses = table[:, :15].reshape(-1, 3, 5)
    assert len(data.cameras) == 20
    np.testing.assert_array_equal(data.bounds, table[:, 15:])
    for cam, pose in zip(data.cameras, poses):
        np.testing.assert_allclose(cam.center, pose[:, 3], rtol=0, atol=1e-12)  # float64 rounding only
        R = cam.cam_to_world[:3, :3]
        np.testing.assert_array_equal(R[:, 0], pose[:, 1])  # right = LLFF col 1
        np.testing.assert_array_equal(R[:, 1], pose[:, 0])  # down  = LLFF col 0
        np.testing.assert_array_equal(R[:, 2], -pose[:, 2])  # forward = -(back)


def test_fern_intrinsics_and_images(fern: tuple[LLFFData, np.ndarray]) -> None:
    data, table = fern
    f_full = table[0, 14]
    assert abs(f_full - 3260.5) < 0.1
    for cam in data.cameras:
        assert (cam.width, cam.height) == (504, 378)
        assert cam.fx == cam.fy == f_full / 8
        assert (cam.cx, cam.cy) == (252.0, 189.0)
    assert len(data.image_paths) == 20
    assert data.image_paths == sorted(data.image_paths)
    assert all(p.parent.name == "images_8" and p.is_file() for p in data.image_paths)
    full = load_llff(FERN / "poses_bounds.npy")
    assert (full.cameras[0].width, full.cameras[0].height, full.cameras[0].fx) == (4032, 3024, f_full)
    assert full.image_paths == []  # no full-size "images" folder in the shared copy


def test_fern_is_forward_facing(fern: tuple[LLFFData, np.ndarray]) -> None:
    data, _ = fern
    forwards = np.stack([c.forward for c in data.cameras])
    mean = forwards.mean(axis=0)
    assert np.all(forwards @ (mean / np.linalg.norm(mean)) > 0.9)


def test_fern_bounds_points_are_seen_by_every_camera(fern: tuple[LLFFData, np.ndarray]) -> None:
    """A point 1.5x the near bound in front of any camera is in front of, and inside, every view."""
    data, _ = fern
    for cam, (near, far) in zip(data.cameras, data.bounds):
        assert 0 < near < far
        point = cam.center + 1.5 * near * cam.forward
        for other in data.cameras:
            uv, depth = other.project(point)
            assert depth[0] > 0
            assert 0 <= uv[0, 0] < other.width and 0 <= uv[0, 1] < other.height


def write_poses_bounds(folder: Path, n: int, hwf: tuple[float, float, float] = (3025.0, 4033.0, 3000.0)) -> Path:
    rng = np.random.default_rng(3)
    rows = []
    for _ in range(n):
        R = random_rotation(rng)  # LLFF columns: down, right, back
        pose = np.concatenate([R, rng.normal(size=(3, 1)), np.array(hwf)[:, None]], axis=1)
        rows.append(np.concatenate([pose.ravel(), [1.0, 10.0]]))
    path = folder / "poses_bounds.npy"
    np.save(path, np.array(rows))
    return path


def test_llff_rounding_and_image_folders(tmp_path: Path) -> None:
    write_poses_bounds(tmp_path, 3)
    data = load_llff(tmp_path, downscale=8)
    cam = data.cameras[0]
    assert (cam.width, cam.height) == (504, 378)  # round(4033/8), round(3025/8)
    assert math.isclose(cam.fx, 3000 * 504 / 4033) and math.isclose(cam.fy, 3000 * 378 / 3025)
    assert data.image_paths == []
    (tmp_path / "images_8").mkdir()
    for name in ("b.png", "a.JPG", "c.jpg", "notes.txt"):
        (tmp_path / "images_8" / name).write_bytes(b"")
    assert [p.name for p in load_llff(tmp_path, downscale=8).image_paths] == ["a.JPG", "b.png", "c.jpg"]
    (tmp_path / "images_8" / "d.png").write_bytes(b"")
    with pytest.raises(CameraFileError, match=r"4 images but poses_bounds.npy has 3 poses"):
        load_llff(tmp_path, downscale=8)
    with pytest.raises(CameraFileError, match="does not exist"):
        load_llff(tmp_path, image_dir="photos")


@pytest.mark.parametrize(
    "array, match",
    [
        (np.zeros((3, 15)), "N x 17"),
        (np.zeros((0, 17)), "N x 17"),
        (np.zeros(17), "N x 17"),
        (np.full((2, 17), np.nan), "non-finite"),
        (np.array([["a"] * 17]), "numbers"),
        (np.zeros((2, 17)), "pose 0: image height, width and focal must be positive"),
        (np.tile(np.r_[np.zeros(4), 378, np.zeros(4), 504, np.zeros(4), 400, 1, 9], (2, 1)), "pose 0: .*orthonormal"),
    ],
)
def test_llff_malformed(tmp_path: Path, array: np.ndarray, match: str) -> None:
    np.save(tmp_path / "poses_bounds.npy", array)
    with pytest.raises(CameraFileError, match=match):
        load_llff(tmp_path)


def test_llff_unreadable(tmp_path: Path) -> None:
    path = write_poses_bounds(tmp_path, 2)
    path.write_bytes(path.read_bytes()[:200])
    with pytest.raises(CameraFileError, match="cannot read"):
        load_llff(path)
    path.write_bytes(b"not numpy at all")
    with pytest.raises(CameraFileError, match="cannot read"):
        load_llff(path)
    np.save(path, np.array([{"a": 1}], dtype=object))
    with pytest.raises(CameraFileError, match="cannot read"):
        load_llff(path)
    with pytest.raises(CameraFileError, match="cannot read"):
        load_llff(tmp_path / "missing")


# ---------------------------------------------------------------------------------------------------
# COLMAP (fixtures written by a minimal writer following COLMAP's documented layout)
# ---------------------------------------------------------------------------------------------------
COLMAP_MODEL_IDS = {"SIMPLE_PINHOLE": 0, "PINHOLE": 1, "SIMPLE_RADIAL": 2, "RADIAL": 3, "OPENCV": 4}
# camera id -> (model, width, height, params)
COLMAP_CAMERAS = {
    1: ("SIMPLE_PINHOLE", 640, 480, [500.0, 320.0, 240.0]),
    2: ("PINHOLE", 800, 600, [610.0, 620.0, 401.5, 299.25]),
    3: ("SIMPLE_RADIAL", 320, 240, [250.0, 160.0, 120.0, 0.0]),
    5: ("RADIAL", 320, 200, [260.0, 161.0, 99.0, 0.0, 0.0]),
    7: ("OPENCV", 1000, 700, [900.0, 905.0, 499.0, 351.0, 0.0, 0.0, 0.0, 0.0]),
}


def quat_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array(
        [
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        ]
    )


def quat_rotation(q: np.ndarray) -> np.ndarray:
    """Rotation matrix by rotating the basis vectors (q v q*), independent of the loader's formula."""
    q = q / np.linalg.norm(q)
    conj = q * [1, -1, -1, -1]
    return np.stack([quat_multiply(quat_multiply(q, np.r_[0.0, e]), conj)[1:] for e in np.eye(3)], axis=1)


def colmap_images(rng: np.random.Generator) -> list[tuple[int, np.ndarray, np.ndarray, int, str]]:
    """(image id, unnormalised quaternion, t, camera id, name); ids and names deliberately out of order."""
    names = ["frame 10.png", "frame_02.png", "a.jpg", "z/last.png", "b.jpg"]
    return [
        (int(i * 3 + 1), rng.normal(size=4) * 2, rng.normal(size=3), cam_id, name)
        for i, (cam_id, name) in enumerate(zip([2, 1, 3, 5, 7], names))
    ]


def write_colmap_text(folder: Path, cameras: dict, images: list, points: tuple[np.ndarray, np.ndarray]) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    lines = ["# Camera list with one line of data per camera:", "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]"]
    lines += [
        f"{cid} {model} {w} {h} " + " ".join(repr(p) for p in params) for cid, (model, w, h, params) in cameras.items()
    ]
    (folder / "cameras.txt").write_text("\n".join(lines) + "\n")
    lines = ["# Image list with two lines of data per image:", "# Number of images: 5"]
    for k, (iid, q, t, cid, name) in enumerate(images):
        lines.append(" ".join([str(iid), *map(repr, q.tolist()), *map(repr, t.tolist()), str(cid), name]))
        lines.append("" if k % 2 else "12.5 30.25 -1 100.0 8.0 4")  # the 2D points line may be empty
    (folder / "images.txt").write_text("\n".join(lines) + "\n")
    xyz, rgb = points
    lines = ["# 3D point list with one line of data per point:"]
    lines += [
        f"{i + 1} {x!r} {y!r} {z!r} {r} {g} {b} 0.5 1 0 3 2"
        for i, ((x, y, z), (r, g, b)) in enumerate(zip(xyz.tolist(), rgb.tolist()))
    ]
    (folder / "points3D.txt").write_text("\n".join(lines) + "\n")


def write_colmap_binary(folder: Path, cameras: dict, images: list, points: tuple[np.ndarray, np.ndarray]) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    out = struct.pack("<Q", len(cameras))
    for cid, (model, w, h, params) in cameras.items():
        out += struct.pack(f"<iiQQ{len(params)}d", cid, COLMAP_MODEL_IDS[model], w, h, *params)
    (folder / "cameras.bin").write_bytes(out)
    out = struct.pack("<Q", len(images))
    for k, (iid, q, t, cid, name) in enumerate(images):
        out += struct.pack("<i4d3di", iid, *q, *t, cid) + name.encode() + b"\0"
        out += struct.pack("<Q", k) + b"".join(struct.pack("<ddq", 1.5 * j, 2.5, j - 1) for j in range(k))
    (folder / "images.bin").write_bytes(out)
    xyz, rgb = points
    out = struct.pack("<Q", len(xyz))
    for i, (p, c) in enumerate(zip(xyz.tolist(), rgb.tolist())):
        track = [(1, i), (4, 2)][: i % 3]
        out += struct.pack("<Q3d3BdQ", i + 1, *p, *c, 0.25, len(track))
        out += b"".join(struct.pack("<ii", *pair) for pair in track)
    (folder / "points3D.bin").write_bytes(out)


def expected_colmap_cameras(images: list) -> list[Camera]:
    cams = []
    for _, q, t, cid, name in sorted(images, key=lambda im: im[4]):
        model, w, h, params = COLMAP_CAMERAS[cid]
        fx, fy, cx, cy = (
            (params[0], params[0], params[1], params[2]) if model.startswith(("SIMPLE", "RADIAL")) else params[:4]
        )
        viewmat = np.eye(4)
        viewmat[:3, :3], viewmat[:3, 3] = quat_rotation(q), t
        cams.append(Camera(viewmat, fx, fy, cx, cy, w, h, name))
    return cams


@pytest.fixture
def colmap_fixture(tmp_path: Path) -> tuple[Path, list, tuple[np.ndarray, np.ndarray]]:
    rng = np.random.default_rng(4)
    images = colmap_images(rng)
    points = (
        rng.normal(size=(7, 3)).astype(np.float32).astype(np.float64),
        rng.integers(0, 256, size=(7, 3)).astype(np.uint8),
    )
    write_colmap_text(tmp_path / "text", COLMAP_CAMERAS, images, points)
    write_colmap_binary(tmp_path / "scene" / "sparse" / "0", COLMAP_CAMERAS, images, points)
    return tmp_path, images, points


def test_colmap_text_and_binary_load_the_known_cameras(colmap_fixture) -> None:
    root, images, _ = colmap_fixture
    expected = expected_colmap_cameras(images)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # all distortion coefficients are zero: no warning
        text = load_colmap(root / "text")
        binary = load_colmap(root / "scene")
    assert [c.name for c in text] == sorted(im[4] for im in images)
    for a, b, c in zip(expected, text, binary):
        assert_same_camera(a, b, atol=1e-12)
        assert_same_camera(b, c, atol=0)


def test_colmap_known_rotation() -> None:
    """A quaternion for 90 degrees about z gives the textbook matrix (checks the w-first order)."""
    s = math.sqrt(0.5)
    np.testing.assert_allclose(quat_rotation(np.array([s, 0, 0, s])), [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-12)


def test_colmap_points(colmap_fixture) -> None:
    root, _, (xyz, rgb) = colmap_fixture
    for folder in (root / "text", root / "scene" / "sparse" / "0"):
        pts, colours = load_colmap_points(folder)
        assert pts.dtype == np.float32 and colours.dtype == np.uint8
        np.testing.assert_array_equal(pts, xyz.astype(np.float32))
        np.testing.assert_array_equal(colours, rgb)


def test_colmap_distortion_warns_once(tmp_path: Path) -> None:
    rng = np.random.default_rng(5)
    cameras = dict(COLMAP_CAMERAS)
    cameras[7] = ("OPENCV", 1000, 700, [900.0, 905.0, 499.0, 351.0, 0.1, -0.02, 0.001, 0.0])
    cameras[3] = ("SIMPLE_RADIAL", 320, 240, [250.0, 160.0, 120.0, 0.05])
    write_colmap_binary(tmp_path, cameras, colmap_images(rng), (np.zeros((0, 3)), np.zeros((0, 3), np.uint8)))
    with pytest.warns(UserWarning, match="distortion is ignored") as record:
        cams = load_colmap(tmp_path)
    assert len(record) == 1 and len(cams) == 5
    assert load_colmap_points(tmp_path)[0].shape == (0, 3)


def test_colmap_binary_truncated(colmap_fixture) -> None:
    root, _, _ = colmap_fixture
    folder = root / "scene" / "sparse" / "0"
    for name in ("cameras.bin", "images.bin"):
        full = (folder / name).read_bytes()
        for cut in (0, 4, 8, 20, len(full) // 2, len(full) - 1):
            (folder / name).write_bytes(full[:cut])
            with pytest.raises(CameraFileError, match=r"truncated|unterminated"):
                load_colmap(folder)
        (folder / name).write_bytes(full + b"\0\0")
        with pytest.raises(CameraFileError, match="trailing"):
            load_colmap(folder)
        (folder / name).write_bytes(full)
    full = (folder / "points3D.bin").read_bytes()
    (folder / "points3D.bin").write_bytes(full[:-3])
    with pytest.raises(CameraFileError, match="truncated"):
        load_colmap_points(folder)


def test_colmap_binary_bad_content(tmp_path: Path) -> None:
    rng = np.random.default_rng(6)
    images = colmap_images(rng)
    write_colmap_binary(tmp_path, COLMAP_CAMERAS, images, (np.zeros((0, 3)), np.zeros((0, 3), np.uint8)))
    cameras_bin = (tmp_path / "cameras.bin").read_bytes()
    (tmp_path / "cameras.bin").write_bytes(cameras_bin[:12] + struct.pack("<i", 9) + cameras_bin[16:])
    with pytest.raises(CameraFileError, match="unsupported model id 9"):
        load_colmap(tmp_path)
    write_colmap_binary(tmp_path, {1: COLMAP_CAMERAS[1]}, images, (np.zeros((0, 3)), np.zeros((0, 3), np.uint8)))
    with pytest.raises(CameraFileError, match=r"uses unknown camera \d"):
        load_colmap(tmp_path)
    bad_images = [(1, np.zeros(4), np.zeros(3), 1, "x.png")]
    write_colmap_binary(tmp_path, COLMAP_CAMERAS, bad_images, (np.zeros((0, 3)), np.zeros((0, 3), np.uint8)))
    with pytest.raises(CameraFileError, match="quaternion"):
        load_colmap(tmp_path)
    write_colmap_binary(tmp_path, COLMAP_CAMERAS, [], (np.zeros((0, 3)), np.zeros((0, 3), np.uint8)))
    with pytest.raises(CameraFileError, match="no images"):
        load_colmap(tmp_path)


@pytest.mark.parametrize(
    "file, content, match",
    [
        ("cameras.txt", "1 PINHOLE 640 480 500 500 320\n", "needs 4 parameters"),
        ("cameras.txt", "1 FISHEYE 640 480 500 500 320 240\n", "not supported"),
        ("cameras.txt", "1 PINHOLE 640 480 500 abc 320 240\n", "line 1"),
        ("cameras.txt", "# comment\n1 PINHOLE 640 480 500 nan 320 240\n", "line 2: non-finite"),
        ("cameras.txt", "1 PINHOLE 640.5 480 500 500 320 240\n", "image size"),
        ("cameras.txt", "1 PINHOLE\n", "expected CAMERA_ID"),
        ("images.txt", "1 1 0 0 0 0 0 0 1\n", "expected IMAGE_ID"),
        ("images.txt", "1 1 0 0 zero 0 0 0 1 a.png\n\n", "line 1"),
        ("points3D.txt", "1 0 0 0 255 0 300 0.1\n", "0..255"),
        ("points3D.txt", "1 0 0 0 255 0\n", "expected POINT3D_ID"),
    ],
)
def test_colmap_text_malformed(colmap_fixture, file: str, content: str, match: str) -> None:
    root, _, _ = colmap_fixture
    folder = root / "text"
    (folder / file).write_text(content)
    with pytest.raises(CameraFileError, match=match):
        load_colmap_points(folder) if file.startswith("points") else load_colmap(folder)


def test_colmap_missing_model(tmp_path: Path) -> None:
    with pytest.raises(CameraFileError, match="no COLMAP model"):
        load_colmap(tmp_path)
    (tmp_path / "cameras.txt").write_text("")
    (tmp_path / "images.txt").write_text("")
    with pytest.raises(CameraFileError, match="points file not found"):
        load_colmap_points(tmp_path)


# ---------------------------------------------------------------------------------------------------
# load_views dispatch
# ---------------------------------------------------------------------------------------------------
def test_load_views_dispatch(tmp_path: Path, colmap_fixture) -> None:
    root, images, _ = colmap_fixture
    expected = expected_colmap_cameras(images)
    for source in (root / "scene", root / "scene" / "sparse" / "0", root / "text", root / "text" / "images.txt"):
        assert [c.name for c in load_views(source)] == [c.name for c in expected]
    json_dir = tmp_path / "model"
    json_dir.mkdir()
    save_cameras_json(json_dir / "cameras.json", expected)
    for source in (json_dir, json_dir / "cameras.json"):
        assert_same_camera(load_views(source)[0], expected[0])
    llff_dir = tmp_path / "llff"
    llff_dir.mkdir()
    write_poses_bounds(llff_dir, 4)
    assert len(load_views(llff_dir)) == len(load_views(llff_dir / "poses_bounds.npy")) == 4
    with pytest.raises(CameraFileError, match="does not exist"):
        load_views(tmp_path / "nothing")
    (tmp_path / "empty").mkdir()
    with pytest.raises(CameraFileError, match="no cameras found"):
        load_views(tmp_path / "empty")
    (tmp_path / "scene.ply").write_bytes(b"ply\n")
    with pytest.raises(CameraFileError, match="not a camera file"):
        load_views(tmp_path / "scene.ply")


def test_load_views_fern() -> None:
    cams = load_views(require(FERN))
    assert len(cams) == 20 and cams[0].width == 4032


# ---------------------------------------------------------------------------------------------------
# Generated views
# ---------------------------------------------------------------------------------------------------
def assert_look_at_centre(cams: list[Camera], center: np.ndarray) -> None:
    for cam in cams:
        uv, depth = cam.project(center)
        np.testing.assert_allclose(uv[0], [cam.width / 2, cam.height / 2], atol=1e-9)
        assert depth[0] > 0


def assert_world_up_is_image_up(cams: list[Camera], center: np.ndarray, up: np.ndarray) -> None:
    for cam in cams:
        (u0, v0), (u1, v1) = cam.project(np.stack([center, center + 0.1 * up]))[0]
        assert v1 < v0 and abs(u1 - u0) < 1e-9, cam.name  # up is straight up in the image


def assert_neighbours_closest(cams: list[Camera], cyclic: bool) -> None:
    centres = np.stack([c.center for c in cams])
    dist = np.linalg.norm(centres[:, None] - centres[None], axis=-1)
    n = len(cams)
    for i in range(n - (0 if cyclic else 1)):
        j = (i + 1) % n
        others = (
            [k for k in range(n) if k not in (i, j, (i - 1) % n)] if cyclic else [k for k in range(n) if abs(k - i) > 1]
        )
        assert all(dist[i, j] < dist[i, k] for k in others), (i, j)


def test_orbit_views() -> None:
    center, up = np.array([1.0, -2.0, 0.5]), np.array([0.0, 0.0, 1.0])
    cams = orbit_views(center, 3.0, 12, width=160, height=120, fov_deg=60, elevation_deg=25)
    assert len(cams) == 12 and len({c.name for c in cams}) == 12
    assert_look_at_centre(cams, center)
    assert_world_up_is_image_up(cams, center, up)
    assert_neighbours_closest(cams, cyclic=True)
    for cam in cams:
        offset = cam.center - center
        assert math.isclose(np.linalg.norm(offset), 3.0)
        assert math.isclose(math.degrees(math.asin(offset[2] / 3.0)), 25.0)
        assert math.isclose(math.degrees(cam.fov_x), 60.0)
    np.testing.assert_allclose(cams[0].forward[:2] / np.linalg.norm(cams[0].forward[:2]), [0, 1], atol=1e-12)


def test_orbit_views_other_up() -> None:
    center, up = np.zeros(3), np.array([0.0, -1.0, 0.0])  # a -y-up world (common for COLMAP scenes)
    cams = orbit_views(center, 2.0, 8, width=64, height=64, up=up)
    assert_look_at_centre(cams, center)
    assert_world_up_is_image_up(cams, center, up)
    assert_neighbours_closest(cams, cyclic=True)


def test_arc_views() -> None:
    center, up = np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, 1.0])
    cams = arc_views(center, 5.0, 9, width=128, height=96, arc_deg=40)
    assert_look_at_centre(cams, center)
    assert_world_up_is_image_up(cams, center, up)
    assert_neighbours_closest(cams, cyclic=False)
    forwards = np.stack([c.forward for c in cams])
    assert np.all(forwards @ np.array([0.0, 1.0, 0.0]) > math.cos(math.radians(21 + 10)))  # all face +y
    azimuths = [math.atan2(c.center[0], -c.center[1]) for c in cams]
    assert azimuths == sorted(azimuths) and math.isclose(math.degrees(azimuths[-1] - azimuths[0]), 40.0)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(radius=0.0), "radius"),
        (dict(n=0), "at least one"),
        (dict(elevation_deg=90.0), "elevation"),
        (dict(fov_deg=180.0), "fov"),
        (dict(up=(0, 0, 0)), "up"),
    ],
)
def test_orbit_views_validation(kwargs: dict, match: str) -> None:
    args = dict(center=(0, 0, 0), radius=1.0, n=4, width=32, height=32) | kwargs
    with pytest.raises(ValueError, match=match):
        orbit_views(**args)


def test_look_at_rejects_view_along_up() -> None:
    with pytest.raises(ValueError, match="parallel"):
        look_at((0, 0, 5), (0, 0, 0), width=32, height=32)


@pytest.fixture(scope="module")
def donut() -> GaussianScene:
    """The shared donut read with numpy (x y z f_dc_0..2 opacity scale_0..2 rot_0..3, float32 LE)."""
    raw = require(DONUT).read_bytes()
    start = raw.index(b"end_header\n") + len(b"end_header\n")
    rows = torch.from_numpy(np.frombuffer(raw[start:], dtype="<f4").reshape(-1, 14).copy())
    return GaussianScene(
        means=rows[:, 0:3],
        quats=rows[:, 10:14],
        log_scales=rows[:, 7:10],
        opacity_logits=rows[:, 6],
        sh_dc=rows[:, 3:6],
        sh_rest=torch.zeros(len(rows), 0, 3),
    )


def bounds_sphere(scene: GaussianScene) -> tuple[np.ndarray, float]:
    lo, hi = (b.double().numpy() for b in scene.bounds(0.98))
    return (lo + hi) / 2, float(np.linalg.norm(hi - lo) / 2)


def sphere_points(center: np.ndarray, radius: float, n: int = 4000) -> np.ndarray:
    v = np.random.default_rng(7).normal(size=(n, 3))
    return center + radius * v / np.linalg.norm(v, axis=1, keepdims=True)


@pytest.mark.parametrize("kind, up", [("auto", (0.0, 0.0, 1.0)), ("orbit", "auto"), ("arc", (0.0, 0.0, 1.0))])
def test_auto_views_frame_the_donut(donut: GaussianScene, kind: str, up) -> None:
    cams = auto_views(donut, 16, width=200, height=150, kind=kind, up=up)
    center, _ = bounds_sphere(donut)
    assert len(cams) == 16
    assert_look_at_centre(cams, center)
    assert_neighbours_closest(cams, cyclic=kind != "arc")
    lo, hi = (b.double().numpy() for b in donut.bounds(0.98))
    corners = np.array([[(lo, hi)[(i >> a) & 1][a] for a in range(3)] for i in range(8)])
    fill = []
    for cam in cams:
        uv, depth = cam.project(corners)
        assert np.all(depth > 0)
        assert np.all((uv >= 0) & (uv <= [cam.width, cam.height])), cam.name
        fill.append(max(np.ptp(uv[:, 0]) / cam.width, np.ptp(uv[:, 1]) / cam.height))
        (_, v0), (_, v1) = cam.project(np.stack([center, center + np.array([0.0, 0.0, 0.01])]))[0]
        assert v1 < v0  # the donut's +z (icing side) is up in every image
    assert min(fill) > 0.6 and max(fill) > 0.7  # the box fills every frame (it is not centred: perspective)


def test_donut_up_axis_is_z(donut: GaussianScene) -> None:
    """The donut's smallest-variance axis is its symmetry axis, world +z (icing on top)."""
    up = estimate_up_axis(donut.means.double().numpy())
    assert up[2] > 0.99
    flipped = estimate_up_axis(donut.means.double().numpy(), prefer=(0.0, 0.0, -1.0))
    np.testing.assert_allclose(flipped, -up)


def test_estimate_up_axis_flat_and_round() -> None:
    rng = np.random.default_rng(8)
    ground = rng.normal(size=(2000, 3)) * [5.0, 4.0, 0.2]
    tilt = look_at((0, 0, 0), (1, 1, 0), width=8, height=8).cam_to_world[:3, :3]  # some rotation
    up = estimate_up_axis(ground @ tilt.T, prefer=(0, 1, 0))
    np.testing.assert_allclose(abs(up @ tilt[:, 2]), 1.0, atol=1e-3)
    assert up @ [0, 1, 0] >= 0
    ball = rng.normal(size=(2000, 3))
    np.testing.assert_array_equal(estimate_up_axis(ball, prefer=(0, 0, 2)), [0, 0, 1])


def test_auto_views_validation() -> None:
    scene = GaussianScene.from_activated(
        torch.rand(50, 3), torch.full((50, 3), 0.01), torch.full((50,), 0.5), torch.rand(50, 3)
    )
    with pytest.raises(ValueError, match="kind"):
        auto_views(scene, 4, kind="spiral")
    with pytest.raises(ValueError, match="up"):
        auto_views(scene, 4, up="sideways")
    cams = auto_views(scene, 4, width=64, height=32, margin=1.0)
    assert all((c.width, c.height) == (64, 32) for c in cams)


@pytest.mark.parametrize("count", [1, 50])
def test_auto_views_frame_one_splat_or_splats_at_one_point(count: int) -> None:
    """A box of no size once put the cameras inside the splat (white views, "behind the cameras"): the views now
    frame a typical splat's own footprint, from outside it."""
    scene = GaussianScene.from_activated(
        torch.full((count, 3), 2.0), torch.full((count, 3), 0.05), torch.full((count,), 0.9), torch.rand(count, 3)
    )
    cameras = auto_views(scene, 4, width=64, height=64)
    out = render(scene, cameras, backend="torch")
    assert all(0.02 < float(alpha.mean()) < 0.5 for alpha in out.alphas)
    assert all(np.linalg.norm(c.center - 2.0) > 3 * 0.05 for c in cameras)


def test_camera_path_through_an_orbit_turns_like_a_denser_orbit() -> None:
    """Slerp between orbit views is exactly the rotation of the orbit view at the middle azimuth; the path
    passes through the given cameras and closes when asked."""
    coarse = orbit_views((0.0, 0.0, 0.0), 3.0, 8, width=64, height=48, elevation_deg=25.0)
    fine = orbit_views((0.0, 0.0, 0.0), 3.0, 32, width=64, height=48, elevation_deg=25.0)
    path = camera_path(coarse, 4, closed=True)
    assert len(path) == 32 and len(camera_path(coarse, 4)) == 29
    for i, cam in enumerate(path):
        rotation = cam.world_to_cam[:3, :3]
        np.testing.assert_allclose(rotation, fine[i].world_to_cam[:3, :3], atol=1e-12)
        np.testing.assert_allclose(rotation @ rotation.T, np.eye(3), atol=1e-12)
        if i % 4 == 0:
            np.testing.assert_allclose(cam.world_to_cam, coarse[i // 4].world_to_cam, atol=1e-12)
    chord_middle = (coarse[0].center + coarse[1].center) / 2.0
    np.testing.assert_allclose(path[2].center, chord_middle, atol=1e-12)
    assert (path[1].fx, path[1].width, path[1].height) == (coarse[0].fx, 64, 48)
    with pytest.raises(ValueError, match="frames_per_gap"):
        camera_path(coarse, 0)
    flipped = Camera.from_cam_to_world(
        coarse[0].cam_to_world[:3, :3] @ np.diag([-1.0, -1.0, 1.0]) @ np.diag([1.0, -1.0, -1.0]),
        coarse[0].center,
        50.0,
        50.0,
        32.0,
        24.0,
        64,
        48,
    )
    with pytest.raises(ValueError, match="180 degrees"):
        camera_path([coarse[0], flipped], 2)


@pytest.mark.parametrize(
    "name, vector", [("+z", (0, 0, 1)), ("-y", (0, -1, 0)), ("+y", (0, 1, 0)), ("-x", (-1, 0, 0)), ("x", (1, 0, 0))]
)
def test_automatic_views_stand_on_the_named_up_axis(name, vector):
    """A capture with -Y up (a 3DGS trainer's) stands upright in views made around --up=-y: every camera sits
    at one height along the axis, above the centre (20 degrees of elevation), its screen's up along the axis."""
    from .test_transfer import blob_scene

    up = np.asarray(vector, float)
    cameras = auto_views(blob_scene(400), 6, up=name)
    lo, hi = (b.double().numpy() for b in blob_scene(400).bounds(0.98))
    heights = [float((c.center - (lo + hi) / 2) @ up) for c in cameras]
    assert min(heights) > 0 and max(heights) - min(heights) < 1e-6 * max(heights)
    assert all(float(-c.world_to_cam[1, :3] @ up) > math.cos(math.radians(21)) for c in cameras)


def test_an_unknown_up_axis_is_refused():
    from gt2gs_blender.core.cameras.axes import axis_vector

    assert axis_vector("-y") == (0.0, -1.0, 0.0) and axis_vector("z") == (0.0, 0.0, 1.0)
    with pytest.raises(ValueError, match="an axis such as"):
        axis_vector("w")


def test_the_run_plans_its_automatic_views_around_the_up_setting():
    """The transfer's Up Axis reaches its views: the plan's cameras are auto_views' around that axis."""
    from gt2gs_blender.core.transfer.config import TransferConfig
    from gt2gs_blender.core.transfer.plan import plan_run

    from .test_transfer import blob_scene

    scene, config = blob_scene(400), TransferConfig(up="-y", resolution=64, n_views=5, layout=False)
    plan = plan_run(scene, np.full((16, 16, 3), 0.5, np.float32), None, config, preview=True)
    expected = auto_views(scene, 5, width=64, height=64, up="-y")
    assert [c.world_to_cam.tolist() for c in plan.cameras] == [c.world_to_cam.tolist() for c in expected]
