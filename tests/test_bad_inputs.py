"""Bad inputs: generated PLY headers, camera files and textures end in the project's error types naming
the file (never another exception, a crash or a hang); inputs are never modified; failed writes leave
nothing behind; the CLI turns all of it into exit code 2 and one line.

Hypothesis generates the bad inputs (about 500 per run); every example runs under a time limit.
"""

from __future__ import annotations

import gzip
import hashlib
import io
import json
import os
import shutil
import struct
import warnings
import zlib
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gt2gs_blender.app.cli import main as cli
from gt2gs_blender.app.cli.demo import torus_scene
from gt2gs_blender.core import atomic
from gt2gs_blender.core.cameras.camera import MAX_IMAGE_SIDE, Camera
from gt2gs_blender.core.cameras.cameras_json import load_cameras_json, save_cameras_json
from gt2gs_blender.core.cameras.files import load_views
from gt2gs_blender.core.errors import CameraFileError, GT2GSError, InputFileError, PlyFormatError
from gt2gs_blender.core.render import render
from gt2gs_blender.core.scene.files import write_splats
from gt2gs_blender.core.scene.gaussians import GaussianScene
from gt2gs_blender.core.scene.ply import read_ply, read_ply_arrays
from gt2gs_blender.core.scene.ply_header import read_ply_header
from gt2gs_blender.core.scene.ply_write import write_ply
from gt2gs_blender.core.transfer.color_transfer import apply_to_scene, fit_color_transform
from gt2gs_blender.core.transfer.config import TransferConfig
from gt2gs_blender.core.transfer.pipeline import transfer
from gt2gs_blender.core.transfer.texture import MAX_SIDE, load_texture, texture_from_array
from gt2gs_blender.core.transfer.visibility import require_visible

from .splat_tools import core_names
from .test_cameras import COLMAP_CAMERAS, colmap_images, write_colmap_binary, write_colmap_text
from .test_ply import MUTATION, mutate, random_columns, raw_ply

FUZZ = settings(
    deadline=None, database=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture]
)


def fuzz(examples: int) -> settings:
    """Hypothesis settings for a bad-input generator: ``examples`` inputs, no deadline or database."""
    return settings(FUZZ, max_examples=examples)


pytestmark = pytest.mark.timeout(120)


def sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def assert_names_file(exc: InputFileError, path: Path) -> None:
    assert exc.path == str(path) and str(path) in str(exc) and "\n" not in str(exc)


# -- PLY: headers generated from the format's grammar ------------------------------------------------

PLY_TYPES = ["char", "uchar", "short", "ushort", "int", "uint", "float", "double", "int8", "float32", "flaot", "list"]
REQUIRED = core_names(0)


@st.composite
def ply_files(draw) -> bytes:
    """A PLY whose header follows (or nearly follows) the grammar, with random counts, types and body."""
    fmt = draw(st.sampled_from(["binary_little_endian", "binary_big_endian", "ascii", "binary", "ascii 2.0"]))
    lines = ["ply", f"format {fmt} 1.0" if " " not in fmt else f"format {fmt}"]
    for _ in range(draw(st.integers(0, 2))):
        lines.append(
            draw(
                st.sampled_from(
                    [
                        "comment made by hypothesis",
                        "obj_info x",
                        "element face 3",
                        "property list uchar int vertex_indices",
                        "element face 4294967295",
                        "element edge -1",
                    ]
                )
            )
        )
    count = draw(st.one_of(st.integers(0, 4), st.sampled_from([2**32 - 1, 2**32, 10**30])))
    lines.append(f"element vertex {count}")
    names = (
        REQUIRED if draw(st.booleans()) else draw(st.lists(st.sampled_from([*REQUIRED, "nx", "f_rest_0"]), max_size=16))
    )
    for name in names:
        ply_type = "float" if draw(st.integers(0, 9)) else draw(st.sampled_from(PLY_TYPES))
        lines.append(f"property list uchar float {name}" if ply_type == "list" else f"property {ply_type} {name}")
    lines += draw(
        st.lists(
            st.sampled_from(["property float extra", "element tail 1", "property uchar t", "end_header"]), max_size=2
        )
    )
    lines.append("end_header")
    header = "\n".join(lines).encode() + b"\n"
    if fmt == "ascii":
        values = draw(
            st.lists(st.sampled_from(["0", "1.5", "-2", "nan", "inf", "1e40", "x", "255"]), max_size=3 * len(names) + 2)
        )
        body = (" ".join(values) + "\n").encode() * draw(st.integers(0, 5))
    else:
        body = draw(st.binary(max_size=4 * len(names) * 5 + 8))
    return header + body


@fuzz(150)
@given(data=ply_files(), drop_invalid=st.booleans(), header_only=st.booleans())
def test_generated_ply_files_load_or_raise_ply_format_error(tmp_path, data, drop_invalid, header_only):
    path = tmp_path / "gen.ply"
    path.write_bytes(data)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            if header_only:
                read_ply_header(path)
                return
            arrays = read_ply_arrays(path, drop_invalid=drop_invalid)
        except PlyFormatError as exc:
            assert_names_file(exc, path)
            return
    assert all("dropped" in str(w.message) for w in caught)
    for key, values in arrays.tensors().items():
        assert values.dtype == np.float32 and np.isfinite(values).all(), key


@pytest.mark.timeout(10)
@pytest.mark.parametrize("tail", [b"", b"\x00", b"\x02\x00\x00\x00\x00\x01\x00\x00\x00"])
def test_a_huge_list_element_count_fails_fast_instead_of_hanging(tmp_path, tail):
    """A 2^32-1 row face element before the vertices once looped four billion times over empty data."""
    props = [(name, "float") for name in REQUIRED]
    data = raw_ply(
        props, random_columns(props, 0), before=(["element face 4294967295", "property list uchar int idx"], tail)
    )
    path = tmp_path / "faces.ply"
    path.write_bytes(data)
    with pytest.raises(PlyFormatError, match="truncated: the data of element 'face' ends early"):
        read_ply(path)


def nonfinite_ply(path: Path, fmt: str = "binary_little_endian") -> Path:
    """Five Gaussians, two of them with NaN or Inf parameters (rows 1 and 3)."""
    props = [(name, "float") for name in REQUIRED] + [("label", "uchar")]
    columns = random_columns(props, 5, seed=3)
    columns["label"] = np.arange(5, dtype=np.uint8)
    columns["scale_1"][1] = np.nan
    columns["rot_2"][3] = -np.inf
    path.write_bytes(raw_ply(props, columns, fmt))
    return path


@pytest.mark.parametrize("fmt", ["binary_little_endian", "ascii"])
def test_non_finite_gaussians_are_rejected_with_counts_or_dropped_and_reported(tmp_path, fmt):
    path = nonfinite_ply(tmp_path / "nan.ply", fmt)
    with pytest.raises(PlyFormatError, match="2 of 5 Gaussians have non-finite values") as info:
        read_ply(path)
    assert_names_file(info.value, path)
    with pytest.warns(UserWarning, match="dropped 2 of 5 Gaussians with non-finite values"):
        scene = read_ply(path, drop_invalid=True)
    assert len(scene) == 3 and scene.extras["label"].tolist() == [0, 2, 4]
    assert all(bool(torch.isfinite(t).all()) for t in scene.tensors().values())


@pytest.mark.parametrize("name", ["nan.ply", "nan.compressed.ply", "nan.spz", "nan.splat"])
def test_no_writer_writes_what_no_reader_takes_back(tmp_path, name):
    """A file the project writes, it can read back: every format refuses NaN or Inf splats, naming the file."""
    scene = torus_scene(n_major=8, n_minor=4)
    means = scene.means.detach().clone()
    means[3, 0] = float("nan")
    with pytest.raises(InputFileError, match="1 of 32 Gaussians have NaN or Inf values") as info:
        write_splats(tmp_path / name, replace(scene, means=means))
    assert_names_file(info.value, tmp_path / name)
    assert list(tmp_path.iterdir()) == []


# -- camera files ----------------------------------------------------------------------------------


def llff_table(n: int = 3) -> np.ndarray:
    """Valid LLFF rows: identity-like poses (down, right, back columns), 480x640, focal 500."""
    table = np.zeros((n, 17))
    for i in range(n):
        rotation = np.stack([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]], axis=1)
        table[i, :15] = np.c_[rotation, [i * 0.1, 0.0, 0.0], [480.0, 640.0, 500.0]].reshape(-1)
        table[i, 15:] = (1.0, 10.0)
    return table


def camera_bases(root: Path) -> dict[str, tuple[str, bytes]]:
    """name -> (file name inside its folder, valid bytes), plus the COLMAP model folders on disk."""
    rng = np.random.default_rng(4)
    images = colmap_images(rng)
    points = (rng.normal(size=(3, 3)), rng.integers(0, 256, size=(3, 3)).astype(np.uint8))
    write_colmap_text(root / "text", COLMAP_CAMERAS, images, points)
    write_colmap_binary(root / "bin", COLMAP_CAMERAS, images, points)
    buffer = io.BytesIO()
    np.save(buffer, llff_table())
    entry = {
        "id": 0,
        "img_name": "a",
        "width": 64,
        "height": 48,
        "position": [0.0, 1.0, 2.0],
        "rotation": np.eye(3).tolist(),
        "fx": 50.0,
        "fy": 51.0,
    }
    bases = {
        "cameras.json": ("cameras.json", json.dumps([entry, {**entry, "cx": 30.5}]).encode()),
        "poses_bounds.npy": ("poses_bounds.npy", buffer.getvalue()),
    }
    for kind, ext in (("text", ".txt"), ("bin", ".bin")):
        for stem in ("cameras", "images"):
            bases[f"{kind}/{stem}{ext}"] = (f"{stem}{ext}", (root / kind / f"{stem}{ext}").read_bytes())
    return bases


@pytest.fixture(scope="module")
def camera_root(tmp_path_factory) -> tuple[Path, dict[str, tuple[str, bytes]]]:
    root = tmp_path_factory.mktemp("cameras")
    return root, camera_bases(root)


def assert_loads_or_camera_file_error(path: Path) -> None:
    """load_views(path) gives valid cameras or a CameraFileError naming a file under the test folder."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # COLMAP distortion warnings
            cameras = load_views(path)
    except CameraFileError as exc:
        assert str(path.parent) in exc.path and exc.path in str(exc) and "\n" not in str(exc)
        return
    assert cameras and all(
        isinstance(c, Camera) and np.isfinite(c.world_to_cam).all() and 0 < c.width <= MAX_IMAGE_SIDE for c in cameras
    )


@fuzz(150)
@given(
    base=st.sampled_from(
        ["cameras.json", "poses_bounds.npy", "text/cameras.txt", "text/images.txt", "bin/cameras.bin", "bin/images.bin"]
    ),
    mutations=st.lists(MUTATION, min_size=1, max_size=4),
)
def test_corrupted_camera_files_load_or_raise_camera_file_error(camera_root, tmp_path, base, mutations):
    root, bases = camera_root
    work = tmp_path / "work"
    shutil.rmtree(work, ignore_errors=True)
    if "/" in base:
        shutil.copytree(root / base.split("/")[0], work)
    else:
        work.mkdir()
    name, data = bases[base]
    (work / name).write_bytes(mutate(data, mutations))
    assert_loads_or_camera_file_error(work / name)


JSON_LEAF = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(10**400), 10**400),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=5),
)
JSON = st.recursive(
    JSON_LEAF,
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=4), inner, max_size=4),
    max_leaves=12,
)
GOOD_ENTRY = {
    "width": 64,
    "height": 48,
    "position": [0.0, 1.0, 2.0],
    "rotation": np.eye(3).tolist(),
    "fx": 50.0,
    "fy": 51.0,
}


@fuzz(100)
@given(key=st.sampled_from([*GOOD_ENTRY, "cx", "cy", "img_name"]), value=JSON, wrap=st.booleans())
def test_cameras_json_with_any_json_value_loads_or_raises_camera_file_error(tmp_path, key, value, wrap):
    path = tmp_path / "cameras.json"
    document = [{**GOOD_ENTRY, key: value}] if wrap else value
    path.write_text(json.dumps(document, allow_nan=True))
    try:
        cameras = load_cameras_json(path)
    except CameraFileError as exc:
        assert_names_file(exc, path)
        return
    assert all(np.isfinite(c.world_to_cam).all() and c.fx > 0 and c.width <= MAX_IMAGE_SIDE for c in cameras)


def npy_header(shape: tuple, descr: str = "<f8") -> bytes:
    buffer = io.BytesIO()
    np.lib.format.write_array_header_1_0(buffer, {"descr": descr, "fortran_order": False, "shape": shape})
    return buffer.getvalue()


def npz_bytes() -> bytes:
    buffer = io.BytesIO()
    np.savez(buffer, poses=llff_table())
    return buffer.getvalue()


BAD_CAMERA_FILES = {
    "cameras.json": {
        "integer-beyond-float": (
            b'[{"width": 64, "height": 48, "position": [0, 0, 0], "fx": 1'
            + b"0" * 400
            + b', "fy": 5, "rotation": [[1,0,0],[0,1,0],[0,0,1]]}]',
            "fx must be a finite",
        ),
        "position-beyond-float": (
            json.dumps([{**GOOD_ENTRY, "position": [0, 0, 0]}])
            .replace("[0, 0, 0]", "[1" + "0" * 400 + ", 0, 0]")
            .encode(),
            "position must be numbers",
        ),
        "nested-too-deeply": (b"[" * 100_000 + b"]" * 100_000, "nested too deeply"),
        "image-too-large": (json.dumps([{**GOOD_ENTRY, "width": 10**15}]).encode(), "exceeds 65536"),
        "utf-16": (json.dumps([GOOD_ENTRY]).encode("utf-16"), "cannot read cameras.json"),
        "empty": (b"", "cannot read cameras.json"),
    },
    "poses_bounds.npy": {
        "header-promises-terabytes": (npy_header((10**12, 17)) + bytes(64), "truncated: the header promises"),
        "corrupt-header-token": (
            npy_header((3, 17))[:10] + b"{'descr': '<f8', 'shape': (3,\x00" + bytes(60),
            "cannot read poses_bounds.npy",
        ),
        "unterminated-header": (npy_header((3, 17)).replace(b"}", b"("), "cannot read poses_bounds.npy"),
        "npz-archive": (npz_bytes(), "cannot read poses_bounds.npy"),
        "complex": (npy_header((2, 17), "<c16") + bytes(2 * 17 * 16), "expected real numbers"),
        "wrong-shape": (npy_header((2, 16)) + bytes(2 * 16 * 8), "N x 17"),
    },
}


@pytest.mark.timeout(20)
@pytest.mark.parametrize("name, case", [(n, c) for n, cases in BAD_CAMERA_FILES.items() for c in cases])
def test_bad_camera_files_raise_camera_file_error(tmp_path, name, case):
    data, match = BAD_CAMERA_FILES[name][case]
    path = tmp_path / name
    path.write_bytes(data)
    with pytest.raises(CameraFileError, match=match) as info:
        load_views(path)
    assert_names_file(info.value, path)


@fuzz(40)
@given(
    name=st.sampled_from(["cams.yaml", "poses.txt", "model.bin", "cameras.xml", "noext", "transforms.json"]),
    data=st.binary(max_size=64),
)
def test_unknown_camera_formats_raise_camera_file_error(tmp_path, name, data):
    path = tmp_path / name
    path.write_bytes(data)
    with pytest.raises(CameraFileError) as info:
        load_views(path)
    assert_names_file(info.value, path)


# -- textures --------------------------------------------------------------------------------------


def encode(path: Path, image: np.ndarray) -> Path:
    ok, data = cv2.imencode(path.suffix, image)
    assert ok
    path.write_bytes(data.tobytes())
    return path


def png_chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def grey_png(width: int, height: int, rows: bytes) -> bytes:
    """An 8-bit greyscale PNG with the given (filter byte + pixels) rows, possibly lying about its size."""
    return b"".join(
        [
            b"\x89PNG\r\n\x1a\n",
            png_chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)),
            png_chunk(b"IDAT", zlib.compress(rows)),
            png_chunk(b"IEND", b""),
        ]
    )


def exr_bytes() -> bytes:
    """A minimal scanline EXR header (OpenCV only needs to see its magic to pick the EXR codec)."""
    return b"v/1\x01\x02\x00\x00\x00" + bytes(200)


def test_a_texture_larger_than_the_limit_is_downscaled_with_a_warning(tmp_path):
    width, height = MAX_SIDE + 808, 1000
    stripes = np.zeros((height, width), np.uint8)
    stripes[:, width // 2 :] = 200
    path = tmp_path / "big.png"
    path.write_bytes(grey_png(width, height, b"".join(b"\x00" + row.tobytes() for row in stripes)))
    with pytest.warns(UserWarning, match=f"is {width}x{height} px; downscaled to {MAX_SIDE}x"):
        texture = load_texture(path)
    assert texture.shape == (round(height * MAX_SIDE / width), MAX_SIDE, 3)
    assert texture[:, :100].max() == 0.0 and np.allclose(texture[:, -100:], 200 / 255)


@pytest.mark.parametrize(
    "case, data, match",
    [
        ("exr", exr_bytes(), "OPENCV_IO_ENABLE_OPENEXR"),
        ("decompression-bomb", grey_png(40000, 30000, bytes(1000)), "more than 2\\^30 pixels"),
        ("truncated-png", grey_png(64, 64, bytes(65 * 64))[:60], "not an image file"),
        ("text", b"P3\nnot really an image", "not an image file"),
    ],
)
def test_undecodable_textures_raise_input_file_error(tmp_path, case, data, match):
    path = tmp_path / f"{case}.img"
    path.write_bytes(data)
    with pytest.raises(InputFileError, match=match) as info:
        load_texture(path)
    assert_names_file(info.value, path)


def test_non_finite_float_texture_samples_are_replaced_with_a_warning(tmp_path):
    image = np.full((80, 80, 3), 0.25, np.float32)
    image[10, 10] = np.nan
    image[20, 20, 1] = np.inf
    path = encode(tmp_path / "float.pfm", image)  # PFM stores float32 samples exactly
    with pytest.warns(UserWarning, match="4 NaN/Inf texture samples were replaced"):
        texture = load_texture(path)
    assert np.isfinite(texture).all()
    assert texture[10, 10].tolist() == [0.0, 0.0, 0.0] and texture[20, 20, 1] == 1.0 and texture[0, 0, 0] == 0.25


def test_a_texture_strip_too_long_to_turn_is_one_line_naming_it(tmp_path, capsys):
    """An 8000 x 4 px strip once reached OpenCV's 32,767 px limit deep in the texture bank (an internal error)."""
    path = encode(tmp_path / "strip.png", np.random.default_rng(0).integers(0, 255, (4, 8000, 3), dtype=np.uint8))
    with pytest.raises(InputFileError, match="8000x4 px, longer than 16:1") as info:
        load_texture(path)
    assert_names_file(info.value, path)
    scene = tmp_path / "scene.ply"
    write_splats(scene, torus_scene(n_major=8, n_minor=4))
    assert cli.main(["transfer", str(scene), str(path), "-o", str(tmp_path / "out.ply"), "--preset", "preview"]) == 2
    assert capsys.readouterr().err.strip() == f"gt2gs: error: {info.value}"


def test_the_api_refuses_a_scene_with_nan_splats_and_zero_views_before_any_work():
    """A scene built in Python can hold NaN (the readers refuse such files); it once surfaced as "radius must be
    positive, got nan". Zero automatic views ran eight, where the command line refuses --views 0."""
    scene = torus_scene(n_major=8, n_minor=4)
    means = scene.means.detach().clone()
    means[5] = float("nan")
    config = TransferConfig(stylise_steps=1, correct_steps=0, rounds=1, resolution=32, n_views=2, backend="torch")
    with pytest.raises(GT2GSError, match="the scene has 1 of 32 Gaussians with NaN or Inf values"):
        transfer(replace(scene, means=means), np.full((16, 16, 3), 0.5), None, config)
    with pytest.raises(GT2GSError, match="views: at least 1 automatic view, got 0"):
        transfer(scene, np.full((16, 16, 3), 0.5), 0, config)


def test_a_texture_array_is_held_to_a_texture_files_rules():
    image = np.full((64, 64, 3), 0.25, np.float32)
    image[3, 3] = np.nan
    with pytest.warns(UserWarning, match="the texture array: 3 NaN/Inf texture samples were replaced"):
        texture = texture_from_array(image)
    assert np.isfinite(texture).all() and texture[3, 3].tolist() == [0.0, 0.0, 0.0]
    assert np.array_equal(texture_from_array(np.full((8, 8, 4), 255, np.uint8)), np.ones((8, 8, 3), np.float32))
    with pytest.raises(InputFileError, match=r"the texture array: has shape \(64, 64\); give an \(H, W, 3\)"):
        texture_from_array(image[..., 0])
    with pytest.raises(InputFileError, match="longer than 16:1"):
        texture_from_array(np.zeros((2, 64, 3)))


MAGIC = [b"", b"\x89PNG\r\n\x1a\n", b"\xff\xd8\xff", b"II*\x00", b"BM", b"RIFF\x00\x00\x00\x00WEBP", b"v/1\x01"]


@fuzz(60)
@given(magic=st.sampled_from(MAGIC), body=st.binary(max_size=200))
def test_garbage_textures_raise_input_file_error(tmp_path, magic, body):
    path = tmp_path / "garbage.png"
    path.write_bytes(magic + body)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            texture = load_texture(path)
    except InputFileError as exc:
        assert_names_file(exc, path)
        return
    assert texture.ndim == 3 and texture.shape[2] == 3 and texture.dtype == np.float32
    assert np.isfinite(texture).all() and texture.min() >= 0.0 and texture.max() <= 1.0


def test_constant_texture_and_constant_scene_colour_transfer_stays_finite(tmp_path):
    path = encode(tmp_path / "flat.png", np.full((96, 96, 3), (20, 120, 220), np.uint8))
    with pytest.warns(UserWarning, match="constant colour"):
        texture = load_texture(path)
    grey = [torch.full((24, 24, 3), 0.5), torch.full((24, 24, 3), 0.5)]
    matrix, offset = fit_color_transform(grey, texture, weights=[torch.ones(24, 24), torch.zeros(24, 24)])
    assert torch.isfinite(matrix).all() and torch.isfinite(offset).all()
    scene = torus_scene(n_major=8, n_minor=4)
    recoloured = apply_to_scene(scene, matrix, offset)
    assert torch.allclose(recoloured.base_colors, torch.tensor([220, 120, 20]) / 255.0 * torch.ones(1, 3), atol=1e-5)


# -- inputs are never modified, outputs are atomic --------------------------------------------------


def tiny_config(tmp_path: Path) -> TransferConfig:
    return TransferConfig(
        resolution=40,
        n_views=2,
        stylise_steps=2,
        n_scales=1,
        n_angles=2,
        texture_height=64,
        evaluate=False,
        gpb=False,
        densify=False,
        cache_dir=str(tmp_path / "banks"),
    )


@pytest.fixture
def inputs(tmp_path: Path) -> tuple[Path, Path]:
    scene_path = tmp_path / "scene.ply"
    write_ply(scene_path, torus_scene(n_major=24, n_minor=12))
    y, x = np.mgrid[0:96, 0:96]
    texture_path = encode(tmp_path / "stripes.png", np.dstack([(x + y) % 32 * 8, x * 2, y * 2]).astype(np.uint8))
    return scene_path, texture_path


def test_transfer_leaves_its_input_files_unchanged(inputs, tmp_path):
    scene_path, texture_path = inputs
    before = {p: (sha256(p), p.stat().st_mtime_ns) for p in inputs}
    scene = read_ply(scene_path)
    result = transfer(scene, texture_path, None, tiny_config(tmp_path))
    assert all(bool(torch.isfinite(t).all()) for t in result.scene.tensors().values())
    assert {p: (sha256(p), p.stat().st_mtime_ns) for p in inputs} == before


def test_cli_transfer_leaves_its_inputs_unchanged_and_writes_only_its_output(inputs, tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("HOME", str(tmp_path / "home"))  # the bank cache goes under the temporary home
    scene_path, texture_path = inputs
    before = {p: sha256(p) for p in inputs}
    out = tmp_path / "out" / "styled.ply"
    out.parent.mkdir()
    code = cli.main(
        [
            "transfer",
            str(scene_path),
            str(texture_path),
            "-o",
            str(out),
            "--steps",
            "2",
            "--resolution",
            "40",
            "--views",
            "2",
            "--preset",
            "preview",
            "--backend",
            "torch",
            "--device",
            "cpu",
            "--split-size",
            "0",
        ]
    )
    assert code == 0, capsys.readouterr().err
    assert {p: sha256(p) for p in inputs} == before
    assert sorted(p.name for p in out.parent.iterdir()) == ["styled.ply"]
    assert len(read_ply(out)) == len(read_ply(scene_path))


def test_a_write_failing_midway_leaves_the_old_file_and_no_temp_file(tmp_path):
    path = tmp_path / "scene.ply"
    path.write_bytes(b"old contents")

    def chunks():
        yield b"ply\n"
        raise OSError(28, "No space left on device")

    with pytest.raises(OSError, match="No space left"):
        atomic.atomic_write(path, chunks())
    assert path.read_bytes() == b"old contents"
    assert [p.name for p in tmp_path.iterdir()] == ["scene.ply"]


def test_cli_transfer_whose_output_write_fails_leaves_nothing(inputs, tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    real_replace = os.replace

    def full_disk(src, dst):
        if str(dst).endswith("styled.ply"):
            raise OSError(28, "No space left on device", str(dst))
        real_replace(src, dst)

    monkeypatch.setattr(atomic.os, "replace", full_disk)
    scene_path, texture_path = inputs
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    code = cli.main(
        [
            "transfer",
            str(scene_path),
            str(texture_path),
            "-o",
            str(out_dir / "styled.ply"),
            "--steps",
            "1",
            "--resolution",
            "32",
            "--views",
            "2",
            "--preset",
            "preview",
            "--backend",
            "torch",
            "--device",
            "cpu",
        ]
    )
    err = capsys.readouterr().err
    errors = [line for line in err.splitlines() if line.startswith("gt2gs: error: ")]
    assert code == 2 and len(errors) == 1 and "Traceback" not in err
    assert "No space left on device" in errors[0] and "styled.ply" in errors[0]
    assert list(out_dir.iterdir()) == []


# -- the CLI contract on these inputs ---------------------------------------------------------------


def cli_run(capsys, *argv: str) -> tuple[int, str, str]:
    code = cli.main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_cli_drop_invalid_reports_the_dropped_count(tmp_path, capsys):
    path = nonfinite_ply(tmp_path / "nan.ply")
    code, out, err = cli_run(capsys, "info", str(path))
    assert code == 2 and out == ""
    assert err.strip().startswith("gt2gs: error: ") and err.count("\n") == 1 and "--drop-invalid" in err
    code, out, err = cli_run(capsys, "info", str(path), "--drop-invalid", "--json")
    assert code == 0 and json.loads(out)["count"] == 3
    assert "gt2gs: warning:" in err and "dropped 2 of 5 Gaussians" in err
    code, out, err = cli_run(
        capsys,
        "render",
        str(path),
        "--drop-invalid",
        "-o",
        str(tmp_path / "r"),
        "--views",
        "1",
        "--width",
        "16",
        "--backend",
        "torch",
        "--device",
        "cpu",
    )
    assert code == 0 and "dropped 2 of 5 Gaussians" in err and (tmp_path / "r" / "view_000.png").is_file()


@pytest.mark.parametrize("case", ["integer-beyond-float", "nested-too-deeply", "image-too-large"])
def test_cli_bad_cameras_json_is_a_user_error(tmp_path, capsys, case):
    scene = tmp_path / "s.ply"
    write_ply(scene, torus_scene(n_major=8, n_minor=4))
    cams = tmp_path / "cameras.json"
    cams.write_bytes(BAD_CAMERA_FILES["cameras.json"][case][0])
    code, _, err = cli_run(capsys, "render", str(scene), "--cameras", str(cams), "-o", str(tmp_path / "o"))
    assert code == 2 and err.count("\n") == 1 and err.startswith("gt2gs: error: ") and str(cams) in err


@pytest.mark.parametrize("data", [exr_bytes(), grey_png(40000, 30000, bytes(100))])
def test_cli_undecodable_texture_is_a_user_error(tmp_path, capsys, data):
    scene = tmp_path / "s.ply"
    write_ply(scene, torus_scene(n_major=8, n_minor=4))
    texture = tmp_path / "t.exr"
    texture.write_bytes(data)
    code, _, err = cli_run(capsys, "transfer", str(scene), str(texture), "-o", str(tmp_path / "o.ply"))
    assert code == 2 and err.count("\n") == 1 and str(texture) in err
    assert not (tmp_path / "o.ply").exists()


def test_cli_ply_with_a_huge_face_count_is_a_user_error(tmp_path, capsys):
    props = [(name, "float") for name in REQUIRED]
    path = tmp_path / "faces.ply"
    path.write_bytes(
        raw_ply(
            props, random_columns(props, 0), before=(["element face 4294967295", "property list uchar int idx"], b"")
        )
    )
    code, _, err = cli_run(capsys, "info", str(path))
    assert code == 2 and "truncated" in err and err.count("\n") == 1


# -- a scene no view sees ---------------------------------------------------------------------------


def cameras_at(forward: float, centres: list[tuple[float, float, float]]) -> list[Camera]:
    """64 px cameras looking along +z (``forward`` 1) or -z (-1), OpenCV axes, at ``centres``."""
    rot = np.diag([1.0, forward, forward])
    return [
        Camera.from_cam_to_world(rot, c, 40.0, 40.0, 32.0, 32.0, 64, 64, name=f"c{i}") for i, c in enumerate(centres)
    ]


BLIND_CAMERAS = {  # the torus lies around the origin in the z = 0 plane, radius 1.4
    "looking-away": cameras_at(-1.0, [(0.3 * i, 0.0, -4.0) for i in range(3)]),
    "scene-outside-the-images": cameras_at(1.0, [(12.0 + i, 0.0, -4.0) for i in range(3)]),
}


def seen_pixels(scene: GaussianScene, cameras: list[Camera]) -> int:
    """Pixels the real renderer covers (alpha > 0) in all the cameras: the oracle of 'visible'."""
    with torch.no_grad():
        return int((render(scene, cameras, render_depth=False, backend="torch").alphas > 0).sum())


@pytest.mark.parametrize("case", sorted(BLIND_CAMERAS))
@pytest.mark.parametrize("switches", [(), ("--no-color-transfer",)])
def test_cli_transfer_with_cameras_that_see_nothing_is_one_error_naming_the_files(
    inputs, tmp_path, capsys, case, switches
):
    """Used to be a bare ValueError from the colour transfer, or (without it) a 'successful' no-op."""
    scene_path, texture_path = inputs
    cameras = BLIND_CAMERAS[case]
    assert seen_pixels(read_ply(scene_path), cameras) == 0
    cams_path = tmp_path / "cameras.json"
    save_cameras_json(cams_path, cameras)
    out = tmp_path / "styled.ply"
    code, _, err = cli_run(
        capsys,
        "transfer",
        str(scene_path),
        str(texture_path),
        "-o",
        str(out),
        "--cameras",
        str(cams_path),
        "--preset",
        "preview",
        "--steps",
        "1",
        "--resolution",
        "32",
        "--backend",
        "torch",
        "--device",
        "cpu",
        *switches,
    )
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err
    assert err == (
        f"gt2gs: error: {scene_path}: no Gaussian is visible in any of the 3 views of {cams_path}: "
        f"all 288 Gaussians are behind the cameras or outside their images; check that the cameras "
        f"belong to this scene (same coordinate frame and scale)\n"
    )
    assert not out.exists()


def test_one_gaussian_seen_by_the_last_camera_is_enough(tmp_path):
    scene = torus_scene(n_major=24, n_minor=12)
    one = scene.subset(torch.arange(len(scene)) == 5)
    corner = cameras_at(1.0, [tuple(float(v) for v in one.means[0] + torch.tensor([0.2, 0.2, -3.0]))])
    cameras = BLIND_CAMERAS["looking-away"] + corner
    assert seen_pixels(one, cameras[:-1]) == 0 and 0 < seen_pixels(one, cameras) < 64 * 64 / 4
    config = TransferConfig(resolution=64, backend="torch", device="cpu")
    require_visible(one, cameras, config, tmp_path / "one.ply", "cameras.json")
    with pytest.raises(InputFileError, match=r"no Gaussian is visible in any of the 3 views of cameras.json"):
        require_visible(one, cameras[:-1], config, tmp_path / "one.ply", "cameras.json")


@pytest.mark.parametrize("case", ["all-transparent", "no-gaussians"])
def test_cli_transfer_of_a_scene_nothing_of_which_can_show_is_one_error(inputs, tmp_path, capsys, case):
    torus = read_ply(inputs[0])
    scene = (
        replace(torus, opacity_logits=torch.full_like(torus.opacity_logits, -8.0))
        if case == "all-transparent"
        else torus.subset(torch.zeros(len(torus), dtype=torch.bool))
    )
    scene_path = tmp_path / "invisible.ply"
    write_ply(scene_path, scene)
    code, _, err = cli_run(
        capsys,
        "transfer",
        str(scene_path),
        str(inputs[1]),
        "-o",
        str(tmp_path / "o.ply"),
        "--views",
        "2",
        "--preset",
        "preview",
        "--resolution",
        "32",
        "--backend",
        "torch",
        "--device",
        "cpu",
    )
    assert code == 2 and err.count("\n") == 1 and err.startswith(f"gt2gs: error: {scene_path}: ")
    assert (
        "all 288 Gaussians are fully transparent (opacity below 1/255)"
        if case == "all-transparent"
        else "the file holds no Gaussians"
    ) in err
    assert not (tmp_path / "o.ply").exists()


# -- broken splat files of every format -------------------------------------------------------------


def broken_splat_files(folder: Path, donut_files: dict) -> dict[str, Path]:
    """One damaged file per kind of damage the splat readers must name: truncation, wrong magic, a zip
    without meta.json, a WebP that does not decode, a chunk count that does not match, an unknown version."""
    import zipfile

    folder.mkdir(exist_ok=True)
    write_splats(folder / "ours.spz", read_ply_arrays(donut_files["ply"]))  # version 3: a gzip stream
    payload = gzip.decompress((folder / "ours.spz").read_bytes())
    sog, compressed = (donut_files[f].read_bytes() for f in ("sog", "compressed-ply"))
    cases = {
        "truncated.spz": gzip.compress(payload[: len(payload) // 2]),
        "magic.spz": gzip.compress(b"XXXX" + payload[4:]),
        "version.spz": gzip.compress(b"NGSP" + (9).to_bytes(4, "little") + payload[8:]),
        "truncated.sog": sog[: len(sog) // 2],
        "truncated.compressed.ply": compressed[: len(compressed) // 2],
        "chunks.compressed.ply": compressed.replace(b"element chunk 179", b"element chunk 178", 1),
        "cut.splat": b"\0" * 40,
    }
    for name, data in cases.items():
        (folder / name).write_bytes(data)
    with zipfile.ZipFile(folder / "no_meta.sog", "w") as z:
        z.writestr("means_l.webp", b"RIFF")
    with zipfile.ZipFile(donut_files["sog"]) as source, zipfile.ZipFile(folder / "webp.sog", "w") as z:
        for item in source.infolist():
            z.writestr(item, b"RIFF\0\0\0\0WEBPbroken" if item.filename.endswith(".webp") else source.read(item))
    return {name: folder / name for name in [*cases, "no_meta.sog", "webp.sog"]}


def test_every_broken_splat_file_is_one_line_naming_it(tmp_path, capsys, donut_files):
    for name, path in broken_splat_files(tmp_path / "broken", donut_files).items():
        code, _, err = cli_run(capsys, "info", str(path))
        assert code == 2 and err.count("\n") == 1, (name, err)
        assert err.startswith(f"gt2gs: error: {path}: "), (name, err)
