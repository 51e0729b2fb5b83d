"""Bad splat, region and texture files through the command line (issue 36): a write never makes a file its own
reader refuses, and every refusal is exit code 2 with one stderr line naming the user's file.

Classes, as the issue numbers them: 2, writers given extreme-but-finite values; 5, inputs that raised internal
errors (a deeply nested meta.json, empty .npy files); 6, errors that did not name the file (an empty scene to
render, positions spz cannot hold, decompression bombs); 9, a compressed PLY whose values overflow float32
when decoded; and the weaker messages (a zero .splat scale, a GIF texture, an SPZ version 4 table of contents
past the end, a semi-transparent texture).
"""

from __future__ import annotations

import gzip
import json
import struct
import zipfile
from pathlib import Path

import cv2
import numpy as np
import pytest

from gt2gs_blender.app.cli import main as cli
from gt2gs_blender.core.scene.files import WRITERS, read_splats, write_splats
from gt2gs_blender.core.transfer.texture import load_texture

from .splat_tools import synthetic_scene
from .test_fuzz_readers import BOMB_IDS, BOMBS, ENDINGS

pytestmark = pytest.mark.timeout(120)


def run(capsys, *argv: str | Path) -> tuple[int, list[str]]:
    """The CLI's exit code and its stderr lines."""
    code = cli.main([str(arg) for arg in argv])
    return code, capsys.readouterr().err.splitlines()


def assert_one_error_naming(code: int, err: list[str], path: Path, *fragments: str) -> None:
    assert code == 2 and len(err) == 1, err
    assert err[0].startswith(f"gt2gs: error: {path}: "), err
    for fragment in fragments:
        assert fragment in err[0], err


# -- 2: writers given extreme-but-finite values ---------------------------------------------------------------

EXTREMES = {
    "log-scale--200": ("log_scales", -200.0),
    "log-scale--1000": ("log_scales", -1000.0),
    "log-scale-89": ("log_scales", 89.0),
    "log-scale-100": ("log_scales", 100.0),
    "log-scale-3e38": ("log_scales", 3e38),
    "position-3e38": ("means", 3e38),
    "position--3e38": ("means", -3e38),
    "opacity-1e30": ("opacity_logits", 1e30),
    "opacity--1e30": ("opacity_logits", -1e30),
    "dc-3e38": ("sh_dc", 3e38),
    "sh-rest--3e38": ("sh_rest", -3e38),
    "zero-quaternion": ("quats", 0.0),
    "denormal-quaternion": ("quats", 1e-45),
}


def extreme_ply(path: Path, field: str, value: float) -> Path:
    """A 300-splat PLY (SH degree 1) with ``value`` in splat 7's ``field`` (every component of a quaternion)."""
    scene = synthetic_scene(300, sh_degree=1, seed=5)
    target = getattr(scene, field).reshape(300, -1)
    if field == "quats":
        target[7] = value
    else:
        target[7, 0] = value
    write_splats(path, scene, "ply")
    return path


@pytest.mark.parametrize("fmt", sorted(WRITERS))
@pytest.mark.parametrize("case", sorted(EXTREMES))
def test_a_converted_file_reads_back_or_the_write_is_refused_naming_it(tmp_path, capsys, case, fmt):
    source = extreme_ply(tmp_path / "in.ply", *EXTREMES[case])
    out = tmp_path / f"out{ENDINGS[fmt]}"
    code, err = run(capsys, "convert", source, out)
    if code == 2:  # refused: positions beyond what spz can store
        assert_one_error_naming(code, err, out, "beyond the")
        assert not out.exists()
        return
    assert code == 0 and all(line.startswith(f"gt2gs: warning: {out}: ") for line in err), err
    back = read_splats(out)
    assert len(back) == 300 and all(np.isfinite(values).all() for values in back.tensors().values())


@pytest.mark.parametrize("case", ["log-scale--200", "log-scale--1000", "log-scale-89", "log-scale-100"])
def test_the_splat_writer_says_how_many_scales_it_clamped_and_to_what(tmp_path, capsys, case):
    out = tmp_path / "out.splat"
    code, err = run(capsys, "convert", extreme_ply(tmp_path / "in.ply", *EXTREMES[case]), out)
    assert code == 0 and f"gt2gs: warning: {out}: splat clamps log scales to -87.3..88.7" in err[-1], err
    assert "1 values clamped" in err[-1] and not any("RuntimeWarning" in line or "overflow" in line for line in err)


# -- 5: inputs that raised internal errors --------------------------------------------------------------------


def deep_meta(folder: Path, zipped: bool) -> Path:
    """A SOG whose meta.json nests objects 100,000 deep (json raises RecursionError on it)."""
    meta = b'{"a": ' * 100_000 + b"1" + b"}" * 100_000
    folder.mkdir()
    if not zipped:
        (folder / "meta.json").write_bytes(meta)
        return folder / "meta.json"
    with zipfile.ZipFile(folder / "deep.sog", "w") as archive:
        archive.writestr("meta.json", meta)
    return folder / "deep.sog"


@pytest.mark.parametrize("zipped", [False, True], ids=["meta.json", "zip"])
def test_a_deeply_nested_meta_json_is_one_error(tmp_path, capsys, zipped):
    path = deep_meta(tmp_path / "sog", zipped)
    assert_one_error_naming(*run(capsys, "info", path), path, "nested too deeply")


def npy_header(shape: tuple, descr: str = "<f4") -> bytes:
    """A .npy version 1.0 header for ``shape`` (no data follows)."""
    text = repr({"descr": descr, "fortran_order": False, "shape": shape}).encode()
    text += b" " * (63 - (10 + len(text)) % 64) + b"\n"
    return b"\x93NUMPY\x01\x00" + struct.pack("<H", len(text)) + text


BAD_NPY = {
    "empty": (b"", "empty or ends early"),
    "magic-only": (b"\x93NUMPY", "as a .npy array"),
    "header-only": (npy_header((10,), "<i8"), "as a .npy array"),
    "huge-shape": (npy_header((10**13,), "|b1") + bytes(16), "as a .npy array"),
    "not-npy": (b"hello, world", "is not a .npy file (it starts with b'hello,')"),
    "pickle": (npy_header((1,), "|O") + b"\x80\x04N.", "as a .npy array"),
}


@pytest.fixture(scope="module")
def small_inputs(tmp_path_factory) -> tuple[Path, Path]:
    """A 300-splat PLY and a 64x64 texture PNG."""
    folder = tmp_path_factory.mktemp("inputs")
    write_splats(folder / "scene.ply", synthetic_scene(300, sh_degree=0))
    rng = np.random.default_rng(0)
    cv2.imwrite(str(folder / "texture.png"), rng.integers(0, 255, (64, 64, 3), np.uint8))
    return folder / "scene.ply", folder / "texture.png"


@pytest.mark.parametrize("role", ["region", "texture"])
@pytest.mark.parametrize("case", sorted(BAD_NPY))
def test_a_bad_npy_region_or_texture_is_one_error_naming_it(tmp_path, capsys, small_inputs, case, role):
    scene, texture = small_inputs
    data, fragment = BAD_NPY[case]
    bad = tmp_path / f"{role}.npy"
    bad.write_bytes(data)
    inputs = [scene, texture, "--region", bad] if role == "region" else [scene, bad]
    code, err = run(capsys, "transfer", *inputs, "-o", tmp_path / "out.ply", "--views", "2")
    assert_one_error_naming(code, err, bad, fragment)
    assert not (tmp_path / "out.ply").exists()


def test_a_npz_region_is_one_error_naming_it(tmp_path, capsys, small_inputs):
    region = tmp_path / "region.npy"
    with region.open("wb") as f:
        np.savez(f, a=np.arange(3))
    code, err = run(capsys, "transfer", *small_inputs, "--region", region, "-o", tmp_path / "o.ply", "--views", "2")
    assert_one_error_naming(code, err, region, "not a .npz archive")


# -- 6: errors that did not name the file ---------------------------------------------------------------------


@pytest.mark.parametrize("ending", [".ply", ".splat", ".spz", ".compressed.ply"])
def test_rendering_an_empty_scene_is_one_error_naming_it(tmp_path, capsys, ending):
    empty = synthetic_scene(300, sh_degree=0)
    for name, values in empty.tensors().items():
        setattr(empty, name, values[:0])
    path = tmp_path / f"empty{ending}"
    write_splats(path, empty)
    assert_one_error_naming(*run(capsys, "render", path, "-o", tmp_path / "views"), path, "holds no splats")


@pytest.mark.parametrize("command", ["info", "render", "convert"])
@pytest.mark.parametrize(("make", "fragment"), BOMBS, ids=BOMB_IDS)
def test_a_decompression_bomb_is_one_error_naming_it_and_its_declared_size(tmp_path, capsys, make, fragment, command):
    bomb = make(tmp_path)
    extra = {"info": [], "render": ["-o", tmp_path / "views"], "convert": [tmp_path / "out.ply"]}[command]
    assert_one_error_naming(*run(capsys, command, bomb, *extra), bomb, fragment, "decompression bomb")


def test_positions_spz_cannot_store_name_the_output(tmp_path, capsys):
    out = tmp_path / "out.spz"
    code, err = run(capsys, "convert", extreme_ply(tmp_path / "in.ply", "means", 3e38), out)
    assert_one_error_naming(code, err, out, "positions reach 3e+38, beyond the +-8388607 units spz can store")


# -- 9: a compressed PLY whose values overflow float32 when decoded -------------------------------------------


def compressed_with_colour_range(path: Path, top: float) -> Path:
    """A 300-splat compressed PLY whose first chunk's colour range reaches ``top``."""
    write_splats(path, synthetic_scene(300, sh_degree=0), "compressed-ply")
    data = bytearray(path.read_bytes())
    start = data.index(b"end_header\n") + len(b"end_header\n")
    struct.pack_into("<f", data, start + 4 * 15, top)  # chunk 0's max_r: the 16th float of the row
    path.write_bytes(bytes(data))
    return path


@pytest.mark.parametrize("command", ["info", "convert"])
@pytest.mark.parametrize("top", [3e38, 1e38, 3.4e38])
def test_a_colour_range_that_overflows_float32_is_said_so(tmp_path, capsys, top, command):
    path = compressed_with_colour_range(tmp_path / "wide.compressed.ply", top)
    extra = [tmp_path / "out.ply"] if command == "convert" else []
    code, err = run(capsys, command, path, *extra)
    assert_one_error_naming(code, err, path, "decode beyond float32's range", "--drop-invalid")
    assert "NaN or Inf" not in err[0]


# -- weaker messages -------------------------------------------------------------------------------------------


@pytest.mark.parametrize("scale", [0.0, -1.0, -0.0])
def test_a_zero_splat_scale_is_called_one(tmp_path, capsys, scale):
    path = tmp_path / "flat.splat"
    write_splats(path, synthetic_scene(10, sh_degree=0))
    data = bytearray(path.read_bytes())
    struct.pack_into("<f", data, 32 * 3 + 12, scale)  # splat 3's first scale
    path.write_bytes(bytes(data))
    assert_one_error_naming(*run(capsys, "info", path), path, "1 of 10 splats have a zero or negative scale")
    assert run(capsys, "info", path, "--drop-invalid", "--json")[0] == 0


def gif_bytes() -> bytes:
    """A 1x1 GIF87a."""
    screen = b"GIF87a\x01\x00\x01\x00\x80\x00\x00\x00\x00\x00\xff\xff\xff"
    return screen + b",\x00\x00\x00\x00\x01\x00\x01\x00\x00\x02\x02D\x01\x00;"


@pytest.mark.parametrize("name", ["texture.gif", "texture.png"])
def test_a_gif_texture_is_called_a_gif(tmp_path, capsys, small_inputs, name):
    gif = tmp_path / name
    gif.write_bytes(gif_bytes())
    code, err = run(capsys, "transfer", small_inputs[0], gif, "-o", tmp_path / "out.ply", "--views", "2")
    assert_one_error_naming(code, err, gif, "a GIF, which is not supported", "PNG")


def v4_with_toc_at(path: Path, toc: int) -> Path:
    """A version 4 spz header (10 points, SH degree 0, 5 streams) whose table of contents is at ``toc``."""
    path.write_bytes(struct.pack("<IIIBBBBI12x", 0x5053474E, 4, 10, 0, 12, 0, 5, toc) + bytes(64))
    return path


@pytest.mark.parametrize("toc", [4, 96, 2**32 - 1])
def test_an_spz_table_of_contents_past_the_end_says_where_it_is(tmp_path, capsys, toc):
    path = v4_with_toc_at(tmp_path / "toc.spz", toc)
    message = f"the table of contents (80 bytes at offset {toc}) does not lie between the 32-byte header and the end"
    assert_one_error_naming(*run(capsys, "info", path), path, message, "96-byte file")


@pytest.mark.parametrize(("alpha", "words"), [(200, "100% of the texture is semi-transparent"), (0, None)])
def test_a_semi_transparent_texture_is_not_called_transparent(tmp_path, alpha, words):
    bgra = np.full((128, 128, 4), 255, np.uint8)
    bgra[:, :, :3] = np.random.default_rng(1).integers(0, 255, (128, 128, 3))
    bgra[:, 64:, 3] = alpha
    bgra[:, :64, 3] = 200 if alpha == 0 else alpha
    path = tmp_path / "a.png"
    cv2.imwrite(str(path), bgra)
    expected = words or "50% of the texture is transparent and 50% semi-transparent"
    with pytest.warns(UserWarning, match=expected):
        load_texture(path)


def test_a_gzip_spz_with_trailing_data_and_no_extension_flag_is_one_error(tmp_path, capsys):
    path = tmp_path / "ours.spz"
    write_splats(path, synthetic_scene(10, sh_degree=0))
    path.write_bytes(gzip.compress(gzip.decompress(path.read_bytes()) + b"trailing"))
    assert_one_error_naming(*run(capsys, "info", path), path, "more data than the 200 bytes that the header's 10")


def test_a_meta_json_that_is_valid_json_of_the_wrong_shape_is_one_error(tmp_path, capsys):
    path = tmp_path / "meta.json"
    path.write_text(json.dumps({"version": 2, "count": 5, "means": []}))
    assert_one_error_naming(*run(capsys, "info", path), path, "has no 'means' section")
