"""Tests of INRIA 3DGS PLY reading and writing (gt2gs_blender.core.scene).

Oracles are independent of the module: a real INRIA file parsed by hand with numpy, and test files
built by a small numpy/struct writer below (``raw_ply``) with hand-written type codes.
"""

from __future__ import annotations

import hashlib
import os
import struct
import warnings
from pathlib import Path

import numpy as np
import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gt2gs_blender.core.errors import PlyFormatError
from gt2gs_blender.core.scene import ply
from gt2gs_blender.core.scene.gaussians import GaussianScene
from gt2gs_blender.core.scene.ply import read_ply
from gt2gs_blender.core.scene.ply_header import PlyProperty, read_ply_header
from gt2gs_blender.core.scene.ply_write import write_ply

from .splat_tools import core_names

SHARED = Path(__file__).resolve().parents[1].parent / "shared"
DONUT = SHARED / "data" / "scenes" / "donut" / "point_cloud.ply"
needs_donut = pytest.mark.skipif(not DONUT.is_file(), reason=f"shared test data not found at {DONUT}")

FORMATS = ("binary_little_endian", "binary_big_endian", "ascii")
BINARY = FORMATS[:2]
# Written out by hand (not imported) so that the tests check the module's table.
TYPE_CODES = {
    "char": "i1",
    "int8": "i1",
    "uchar": "u1",
    "uint8": "u1",
    "short": "i2",
    "int16": "i2",
    "ushort": "u2",
    "uint16": "u2",
    "int": "i4",
    "int32": "i4",
    "uint": "u4",
    "uint32": "u4",
    "float": "f4",
    "float32": "f4",
    "double": "f8",
    "float64": "f8",
}


def random_columns(props: list[tuple[str, str]], n: int, seed: int = 0) -> dict[str, np.ndarray]:
    """Random values of each property's type."""
    rng = np.random.default_rng(seed)
    columns = {}
    for name, ply_type in props:
        dtype = np.dtype(TYPE_CODES[ply_type])
        if dtype.kind == "f":
            columns[name] = rng.standard_normal(n).astype(dtype)
        else:
            info = np.iinfo(dtype)
            columns[name] = rng.integers(info.min, int(info.max) + 1, n, dtype=np.int64).astype(dtype)
    return columns


def body_bytes(props: list[tuple[str, str]], columns: dict[str, np.ndarray], fmt: str) -> bytes:
    """Vertex data in ``fmt``, written independently of the module."""
    n = len(next(iter(columns.values()))) if columns else 0
    if fmt == "ascii":
        rows = []
        for i in range(n):
            rows.append(
                " ".join(
                    repr(float(columns[name][i])) if TYPE_CODES[t][0] == "f" else str(int(columns[name][i]))
                    for name, t in props
                )
            )
        return "".join(row + "\n" for row in rows).encode()
    endian = "<" if fmt == "binary_little_endian" else ">"
    records = np.empty(n, np.dtype([(name, endian + TYPE_CODES[t]) for name, t in props]))
    for name, _ in props:
        records[name] = columns[name]
    return records.tobytes()


def raw_ply(
    props: list[tuple[str, str]],
    columns: dict[str, np.ndarray],
    fmt: str = "binary_little_endian",
    *,
    n: int | None = None,
    header_lines: tuple[str, ...] = (),
    before: tuple[list[str], bytes] | None = None,
    after: tuple[list[str], bytes] | None = None,
    newline: str = "\n",
) -> bytes:
    """A PLY file: optional extra header lines (comments), elements before/after 'vertex'."""
    count = n if n is not None else (len(next(iter(columns.values()))) if columns else 0)
    lines = ["ply", f"format {fmt} 1.0", *header_lines]
    lines += before[0] if before else []
    lines += [f"element vertex {count}", *(f"property {t} {name}" for name, t in props)]
    lines += after[0] if after else []
    lines.append("end_header")
    header = "".join(line + newline for line in lines).encode()
    return header + (before[1] if before else b"") + body_bytes(props, columns, fmt) + (after[1] if after else b"")


def make_scene(n: int, degree: int, *, normals: bool = False, extras: bool = False, seed: int = 0) -> GaussianScene:
    """A random float32 scene; extras of types uchar, int and double (and float normals)."""
    rng = np.random.default_rng(seed)

    def randn(*shape: int) -> torch.Tensor:
        return torch.from_numpy(rng.standard_normal(shape).astype(np.float32))

    extra: dict[str, np.ndarray] = {}
    if normals:
        extra.update({axis: rng.standard_normal(n).astype(np.float32) for axis in ("nx", "ny", "nz")})
    if extras:
        extra["confidence"] = rng.integers(0, 256, n).astype(np.uint8)
        extra["label"] = rng.integers(-(2**31), 2**31, n).astype(np.int32)
        extra["weight"] = rng.standard_normal(n)
    return GaussianScene(
        means=randn(n, 3),
        quats=randn(n, 4),
        log_scales=randn(n, 3),
        opacity_logits=randn(n),
        sh_dc=randn(n, 3),
        sh_rest=randn(n, (degree + 1) ** 2 - 1, 3),
        extras=extra,
    )


def assert_same_scene(a: GaussianScene, b: GaussianScene) -> None:
    for key, value in a.tensors().items():
        other = b.tensors()[key]
        assert other.dtype == torch.float32, key
        assert torch.equal(value.to(torch.float32), other), key
    assert list(a.extras) == list(b.extras)
    for key, value in a.extras.items():
        assert b.extras[key].dtype == value.dtype, key
        np.testing.assert_array_equal(b.extras[key], value, err_msg=key)


def header_text(path: Path) -> str:
    data = path.read_bytes()
    return data[: data.index(b"end_header\n") + len(b"end_header\n")].decode()


def sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


# -- the real INRIA file -------------------------------------------------------------------------------


@needs_donut
def test_donut_matches_a_hand_parsed_reading_of_its_bytes():
    data = DONUT.read_bytes()
    start = data.index(b"end_header\n") + len(b"end_header\n")
    dtype = np.dtype([(name, "<f4") for name in core_names(0)])
    oracle = np.frombuffer(data, dtype, count=45624, offset=start)
    assert len(data) == start + 45624 * dtype.itemsize

    scene = read_ply(DONUT)

    assert len(scene) == 45624 and scene.sh_degree == 0 and scene.extras == {}
    assert scene.sh_rest.shape == (45624, 0, 3)
    expected = {
        "means": ["x", "y", "z"],
        "sh_dc": ["f_dc_0", "f_dc_1", "f_dc_2"],
        "opacity_logits": ["opacity"],
        "log_scales": ["scale_0", "scale_1", "scale_2"],
        "quats": ["rot_0", "rot_1", "rot_2", "rot_3"],
    }
    for key, names in expected.items():
        want = np.stack([oracle[name] for name in names], axis=1).astype(np.float32)
        got = scene.tensors()[key].numpy().reshape(len(scene), -1)
        np.testing.assert_array_equal(got, want, err_msg=key)
    assert scene.ply_layout == tuple((name, "float") for name in core_names(0))


@needs_donut
def test_donut_rewrite_is_byte_exact(tmp_path):
    out = tmp_path / "donut.ply"
    write_ply(out, read_ply(DONUT))
    assert out.read_bytes() == DONUT.read_bytes()


@needs_donut
def test_donut_header_without_loading_the_data():
    header = read_ply_header(DONUT)
    data = DONUT.read_bytes()
    assert header.format == "binary_little_endian"
    assert header.vertex_count == 45624
    assert header.header_size == data.index(b"end_header\n") + len(b"end_header\n")
    assert header.properties == tuple((name, "float") for name in core_names(0))
    assert [(e.name, e.count) for e in header.elements] == [("vertex", 45624)]


# -- generated files: round trips ----------------------------------------------------------------------


@pytest.mark.parametrize("fmt", FORMATS)
@pytest.mark.parametrize("normals", [False, True], ids=["no-normals", "normals"])
@pytest.mark.parametrize("degree", [0, 1, 2, 3])
def test_round_trip_keeps_every_value(tmp_path, degree, normals, fmt):
    scene = make_scene(7, degree, normals=normals, extras=True, seed=degree)
    path = tmp_path / "scene.ply"
    write_ply(path, scene, fmt=fmt)
    loaded = read_ply(path)
    assert_same_scene(scene, loaded)
    assert loaded.sh_degree == degree
    names = [name for name, _ in loaded.ply_layout]
    normal_names = ["nx", "ny", "nz"] if normals else []
    k = (degree + 1) ** 2 - 1
    assert names == [*core_names(k)[:3], *normal_names, *core_names(k)[3:], "confidence", "label", "weight"]
    assert dict(loaded.ply_layout)["confidence"] == "uchar"
    assert dict(loaded.ply_layout)["label"] == "int"
    assert dict(loaded.ply_layout)["weight"] == "double"


@pytest.mark.parametrize("fmt", FORMATS)
@pytest.mark.parametrize("degree", [0, 1, 2, 3])
def test_rewriting_an_unchanged_scene_is_byte_exact(tmp_path, degree, fmt):
    first, second = tmp_path / "first.ply", tmp_path / "second.ply"
    write_ply(first, make_scene(5, degree, normals=True, extras=True), fmt=fmt)
    write_ply(second, read_ply(first), fmt=fmt)
    assert second.read_bytes() == first.read_bytes()


@pytest.mark.parametrize("fmt", BINARY)
def test_foreign_layout_is_kept_byte_for_byte(tmp_path, fmt):
    """Shuffled order, type aliases, double core values and every extra type survive unchanged."""
    props = [
        ("rot_3", "float32"),
        ("opacity", "float"),
        ("tag", "char"),
        ("x", "double"),
        ("y", "float"),
        ("f_dc_2", "float"),
        ("f_dc_0", "float"),
        ("z", "float64"),
        ("f_dc_1", "float"),
        ("scale_2", "float"),
        ("u8", "uint8"),
        ("scale_0", "float"),
        ("scale_1", "float"),
        ("s16", "short"),
        ("u16", "ushort"),
        ("i32", "int32"),
        ("u32", "uint"),
        ("rot_0", "float"),
        ("rot_1", "float"),
        ("rot_2", "float"),
        ("d", "double"),
        ("i8", "int8"),
        ("f", "float"),
    ]
    props += [(f"f_rest_{i}", "float") for i in reversed(range(9))]
    columns = random_columns(props, 6, seed=3)
    for axis in "xz":  # core values are float32 in memory: exact only for doubles that are float32 values
        columns[axis] = columns[axis].astype(np.float32).astype(np.float64)
    path, out = tmp_path / "in.ply", tmp_path / "out.ply"
    path.write_bytes(raw_ply(props, columns, fmt))

    scene = read_ply(path)

    assert scene.ply_layout == tuple(props)
    assert list(scene.extras) == ["tag", "u8", "s16", "u16", "i32", "u32", "d", "i8", "f"]
    for name, values in scene.extras.items():
        assert values.dtype == np.dtype(TYPE_CODES[dict(props)[name]])  # native byte order
        np.testing.assert_array_equal(values, columns[name])
    np.testing.assert_array_equal(scene.means.numpy(), np.stack([columns[a] for a in "xyz"], 1).astype(np.float32))
    write_ply(out, scene, fmt=fmt)
    assert out.read_bytes() == path.read_bytes()


def test_f_rest_is_read_channel_major(tmp_path):
    """f_rest_0..K-1 are red's coefficients, then green, then blue: sh_rest[n, k, c] = f_rest_{c*K+k}."""
    k = 3
    props = [(name, "float") for name in core_names(k)]
    columns = random_columns(props, 2)
    for i in range(3 * k):
        columns[f"f_rest_{i}"] = np.array([i, 100 + i], np.float32)
    path = tmp_path / "sh1.ply"
    path.write_bytes(raw_ply(props, columns))
    rest = read_ply(path).sh_rest.numpy()
    for j in range(k):
        for c in range(3):
            assert rest[0, j, c] == c * k + j and rest[1, j, c] == 100 + c * k + j


def test_ascii_to_binary_to_ascii_preserves_values(tmp_path):
    scene = make_scene(9, 3, normals=True, extras=True)
    a1, b, a2 = tmp_path / "a1.ply", tmp_path / "b.ply", tmp_path / "a2.ply"
    write_ply(a1, scene, fmt="ascii")
    write_ply(b, read_ply(a1), fmt="binary_little_endian")
    write_ply(a2, read_ply(b), fmt="ascii")
    assert_same_scene(scene, read_ply(a2))
    assert a2.read_bytes() == a1.read_bytes()
    assert header_text(b).startswith("ply\nformat binary_little_endian 1.0\n")


def test_big_endian_reads_the_same_as_little_endian(tmp_path):
    props = [(name, "float") for name in core_names(8)] + [("nx", "float"), ("id", "uint"), ("w", "double")]
    columns = random_columns(props, 11, seed=5)
    little, big = tmp_path / "le.ply", tmp_path / "be.ply"
    little.write_bytes(raw_ply(props, columns, "binary_little_endian"))
    big.write_bytes(raw_ply(props, columns, "binary_big_endian"))
    assert little.read_bytes() != big.read_bytes()
    assert_same_scene(read_ply(little), read_ply(big))


def test_ascii_file_from_another_writer_reads_exactly(tmp_path):
    props = [(name, "float") for name in core_names(3)] + [("c", "uchar"), ("i", "int"), ("d", "double")]
    columns = random_columns(props, 4, seed=9)
    path = tmp_path / "ascii.ply"
    path.write_bytes(raw_ply(props, columns, "ascii"))
    scene = read_ply(path)
    assert read_ply_header(path).format == "ascii"
    np.testing.assert_array_equal(scene.quats.numpy(), np.stack([columns[f"rot_{i}"] for i in range(4)], 1))
    for name in ("c", "i", "d"):
        np.testing.assert_array_equal(scene.extras[name], columns[name])


def test_double_core_properties_load_as_float32_and_stay_double_on_rewrite(tmp_path):
    props = [(name, "double") for name in core_names(0)]
    columns = random_columns(props, 3)
    path, out = tmp_path / "double.ply", tmp_path / "out.ply"
    path.write_bytes(raw_ply(props, columns))
    scene = read_ply(path)
    assert scene.means.dtype == torch.float32
    np.testing.assert_array_equal(scene.opacity_logits.numpy(), columns["opacity"].astype(np.float32))
    write_ply(out, scene)
    assert header_text(out) == header_text(path)


def test_changed_scene_is_written_in_canonical_order(tmp_path):
    props = [("opacity", "float"), ("label", "uchar")]
    props += [(name, "float") for name in core_names(0) if name != "opacity"]
    path, out = tmp_path / "in.ply", tmp_path / "out.ply"
    path.write_bytes(raw_ply(props, random_columns(props, 4)))
    scene = read_ply(path).with_sh_degree(1)
    write_ply(out, scene)
    assert read_ply_header(out).properties == tuple([(name, "float") for name in core_names(3)] + [("label", "uchar")])

    scene = read_ply(path)
    scene.extras["label"] = scene.extras["label"].astype(np.int16)
    write_ply(out, scene)
    assert read_ply_header(out).properties[-1] == ("label", "short")
    assert read_ply_header(out).properties[0] == ("x", "float")


def test_other_elements_are_parsed_and_skipped(tmp_path):
    """A face element with a list property before 'vertex' and an edge element after it."""
    props = [(name, "float") for name in core_names(3)] + [("nx", "float")]
    columns = random_columns(props, 5, seed=2)
    face_header = ["element face 2", "property list uchar int vertex_indices", "property uchar flags"]
    edge_header = ["element edge 1", "property int a", "property int b"]
    for fmt in FORMATS:
        if fmt == "ascii":
            face, edge = b"3 0 1 2 7\n4 0 1 2 3 9\n", b"0 1\n"
        else:
            e = "<" if fmt == "binary_little_endian" else ">"
            face = struct.pack(e + "B3iB", 3, 0, 1, 2, 7) + struct.pack(e + "B4iB", 4, 0, 1, 2, 3, 9)
            edge = struct.pack(e + "2i", 0, 1)
        path = tmp_path / f"{fmt}.ply"
        path.write_bytes(raw_ply(props, columns, fmt, before=(face_header, face), after=(edge_header, edge)))
        header = read_ply_header(path)
        assert [(el.name, el.count) for el in header.elements] == [("face", 2), ("vertex", 5), ("edge", 1)]
        assert header.elements[0].properties[0] == PlyProperty("vertex_indices", "int", "uchar")
        scene = read_ply(path)
        np.testing.assert_array_equal(scene.sh_dc[:, 1].numpy(), columns["f_dc_1"])
        np.testing.assert_array_equal(scene.extras["nx"], columns["nx"])


@pytest.mark.parametrize("fmt", FORMATS)
def test_comments_and_crlf_lines_are_accepted(tmp_path, fmt):
    props = [(name, "float") for name in core_names(0)]
    columns = random_columns(props, 3)
    path = tmp_path / "crlf.ply"
    comments = ("comment made by hand", "obj_info x")
    if fmt == "ascii":  # CRLF in the data too, and no newline after the last row
        data = raw_ply(props, columns, fmt, header_lines=comments).replace(b"\n", b"\r\n")[:-2]
    else:
        data = raw_ply(props, columns, fmt, header_lines=comments, newline="\r\n")
    path.write_bytes(data)
    header = read_ply_header(path)
    assert header.comments == ("comment made by hand", "obj_info x")
    np.testing.assert_array_equal(read_ply(path).means[:, 2].numpy(), columns["z"])


@pytest.mark.parametrize("fmt", FORMATS)
def test_empty_scene_round_trips(tmp_path, fmt):
    path = tmp_path / "empty.ply"
    write_ply(path, make_scene(0, 2, normals=True, extras=True), fmt=fmt)
    scene = read_ply(path)
    assert len(scene) == 0 and scene.sh_degree == 2 and list(scene.extras)[:3] == ["nx", "ny", "nz"]


def test_reading_leaves_the_file_unchanged(tmp_path):
    path = tmp_path / "scene.ply"
    write_ply(path, make_scene(20, 3, normals=True, extras=True))
    before, mtime = sha256(path), path.stat().st_mtime_ns
    read_ply(path)
    read_ply_header(path)
    assert sha256(path) == before and path.stat().st_mtime_ns == mtime


def test_writing_leaves_the_scene_unchanged(tmp_path):
    scene = make_scene(6, 1, normals=True, extras=True)
    scene.ply_layout = (("bogus", "float"),)
    copy = scene.clone()
    write_ply(tmp_path / "out.ply", scene, fmt="binary_big_endian")
    write_ply(tmp_path / "out.ply", scene, fmt="ascii")
    assert_same_scene(copy, scene)
    assert scene.ply_layout == (("bogus", "float"),)


def test_float64_scene_is_written_as_float32(tmp_path):
    scene = make_scene(4, 0).to(dtype=torch.float64)
    path = tmp_path / "f64.ply"
    write_ply(path, scene)
    assert {t for _, t in read_ply_header(path).properties} == {"float"}
    assert_same_scene(scene, read_ply(path))


def test_unknown_write_format_is_rejected(tmp_path):
    with pytest.raises(ValueError, match="binary_little_endian"):
        write_ply(tmp_path / "x.ply", make_scene(2, 0), fmt="binary")
    assert list(tmp_path.iterdir()) == []


# -- malformed files ------------------------------------------------------------------------------------

GOOD_PROPS = [(name, "float") for name in core_names(0)] + [("label", "uchar")]


def good(fmt: str = "binary_little_endian", props: list[tuple[str, str]] | None = None, **kwargs) -> bytes:
    """A valid 2-Gaussian file to break."""
    props = GOOD_PROPS if props is None else props
    return raw_ply(props, random_columns(props, 2), fmt, **kwargs)


def ascii_with_first_value(token: bytes) -> bytes:
    data = good("ascii")
    start = data.index(b"end_header\n") + len(b"end_header\n")
    return data[:start] + token + b" " + data[start:].split(b" ", 1)[1]


def with_type(name: str, ply_type: str) -> list[tuple[str, str]]:
    return [(n, ply_type if n == name else t) for n, t in GOOD_PROPS]


def nonfinite_file() -> bytes:
    columns = random_columns(GOOD_PROPS, 5)
    columns["f_dc_1"][1] = np.nan
    columns["x"][3] = np.inf
    return raw_ply(GOOD_PROPS, columns)


MALFORMED = {
    "not-ply": (b"hello world\n", "not a PLY"),
    "empty": (b"", "empty"),
    "bad-format-name": (good().replace(b"binary_little_endian", b"binary_middle_endian"), "format"),
    "format-no-version": (good().replace(b"binary_little_endian 1.0", b"binary_little_endian"), "format"),
    "no-format-line": (good().replace(b"format binary_little_endian 1.0\n", b""), "no 'format' line"),
    "two-format-lines": (good(header_lines=("format ascii 1.0",)), "second 'format'"),
    "no-end-header": (good()[: good().index(b"end_header")], "end_header"),
    "header-too-long": (good(header_lines=("comment " + "x" * 70,) * 1000), "too long"),
    "non-ascii-header": (good(header_lines=("comment caf\xe9",)).replace(b"caf\xc3\xa9", b"caf\xe9"), "ASCII"),
    "no-vertex-element": (good().replace(b"element vertex", b"element points"), "element vertex"),
    "negative-count": (good().replace(b"element vertex 2", b"element vertex -3"), "negative"),
    "non-integer-count": (good().replace(b"element vertex 2", b"element vertex two"), "element"),
    "absurd-count": (good().replace(b"element vertex 2", b"element vertex 99999999999"), "implausibly large"),
    "duplicate-element": (good(after=(["element vertex 0"], b"")), "duplicate element"),
    "truncated-binary": (good()[:-5], "truncated"),
    "count-too-large": (good().replace(b"element vertex 2", b"element vertex 3"), "truncated"),
    "truncated-ascii-rows": (good("ascii").replace(b"element vertex 2", b"element vertex 3"), "truncated"),
    "ascii-missing-value": (good("ascii").rsplit(b" ", 1)[0] + b"\n", "ASCII"),
    "ascii-not-a-number": (ascii_with_first_value(b"abc"), "ASCII"),
    "ascii-garbage-value": (good("ascii")[:-3] + b"zz\n", "ASCII"),
    "ascii-non-ascii-data": (good("ascii")[:-3] + b"\xff\xfe\n", "ASCII"),
    "ascii-int-not-integer": (good("ascii")[:-1].rsplit(b" ", 1)[0] + b" 1.5\n", "integers"),
    "ascii-int-out-of-range": (good("ascii")[:-1].rsplit(b" ", 1)[0] + b" 300\n", "integers"),
    "unknown-type": (good().replace(b"property float y", b"property flaot y"), "unknown property type"),
    "duplicate-property": (good().replace(b"property float y", b"property float x"), "duplicate property"),
    "bad-property-line": (good().replace(b"property float y", b"property float y z"), "property"),
    "unknown-keyword": (good().replace(b"element vertex", b"elemnt vertex"), "unknown header keyword"),
    "property-before-element": (good(header_lines=("property float q",)), "before any"),
    "list-count-float": (good(before=(["element face 0", "property list float int idx"], b"")), "count type"),
    "vertex-list": (good().replace(b"property uchar label", b"property list uchar int label"), "list"),
    "truncated-list-element": (
        good(before=(["element face 3", "property list uchar int idx"], b"\x01\0\0\0\0")),
        "truncated",
    ),
    "missing-required": (
        good(props=[p for p in GOOD_PROPS if p[0] not in ("scale_1", "rot_3")]),
        "missing required properties scale_1, rot_3",
    ),
    "non-float-required": (good(props=with_type("opacity", "uchar")), "float or double: opacity (uchar)"),
    "f-rest-count": (good(props=GOOD_PROPS + [(f"f_rest_{i}", "float") for i in range(10)]), "f_rest"),
    "f-rest-names": (good(props=GOOD_PROPS + [(f"f_rest_{i + 1}", "float") for i in range(9)]), "f_rest"),
    "f-rest-int": (good(props=GOOD_PROPS + [(f"f_rest_{i}", "short") for i in range(9)]), "f_rest_0 (short)"),
    "non-finite": (nonfinite_file(), "2 of 5 Gaussians have non-finite"),
}


@pytest.mark.parametrize("case", MALFORMED)
def test_malformed_file_raises_ply_format_error(tmp_path, case):
    data, keyword = MALFORMED[case]
    path = tmp_path / f"{case}.ply"
    path.write_bytes(data)
    with pytest.raises(PlyFormatError) as info:
        read_ply(path)
    message = str(info.value)
    assert f"{case}.ply" in message and info.value.path == str(path)
    assert keyword in message


def test_non_finite_message_suggests_drop_invalid(tmp_path):
    path = tmp_path / "nan.ply"
    path.write_bytes(nonfinite_file())
    with pytest.raises(PlyFormatError, match="--drop-invalid"):
        read_ply(path)


def test_double_too_large_for_float32_counts_as_non_finite(tmp_path):
    props = with_type("scale_0", "double")
    columns = random_columns(props, 3)
    columns["scale_0"][2] = 1e300
    path = tmp_path / "huge.ply"
    path.write_bytes(raw_ply(props, columns))
    with pytest.raises(PlyFormatError, match="1 of 3 Gaussians"):
        read_ply(path)


@pytest.mark.parametrize("header_only", [False, True], ids=["read_ply", "read_ply_header"])
def test_paths_that_are_not_files(tmp_path, header_only):
    reader = read_ply_header if header_only else read_ply
    with pytest.raises(PlyFormatError, match="no such file") as info:
        reader(tmp_path / "missing.ply")
    assert "missing.ply" in str(info.value)
    (tmp_path / "folder.ply").mkdir()
    with pytest.raises(PlyFormatError, match="directory") as info:
        reader(tmp_path / "folder.ply")
    assert "folder.ply" in str(info.value)


def test_header_checks_apply_to_read_ply_header(tmp_path):
    path = tmp_path / "bad.ply"
    path.write_bytes(MALFORMED["unknown-type"][0])
    with pytest.raises(PlyFormatError, match="unknown property type"):
        read_ply_header(path)


def test_trailing_bytes_after_vertex_data_are_ignored(tmp_path):
    path = tmp_path / "padded.ply"
    path.write_bytes(good() + b"\x00" * 13)
    assert len(read_ply(path)) == 2


# -- drop_invalid -----------------------------------------------------------------------------------------


def test_drop_invalid_drops_the_bad_gaussians_with_a_warning(tmp_path):
    columns = random_columns(GOOD_PROPS, 5)
    columns["f_dc_1"][1] = np.nan
    columns["x"][3] = -np.inf
    path = tmp_path / "nan.ply"
    path.write_bytes(raw_ply(GOOD_PROPS, columns))
    with pytest.warns(UserWarning, match="dropped 2 of 5"):
        scene = read_ply(path, drop_invalid=True)
    keep = [0, 2, 4]
    assert len(scene) == 3
    np.testing.assert_array_equal(scene.means[:, 0].numpy(), columns["x"][keep])
    np.testing.assert_array_equal(scene.extras["label"], columns["label"][keep])


def test_drop_invalid_is_silent_when_all_values_are_finite(tmp_path):
    path = tmp_path / "ok.ply"
    path.write_bytes(good())
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert len(read_ply(path, drop_invalid=True)) == 2


def test_non_finite_extras_are_kept_as_they_are(tmp_path):
    props = [*GOOD_PROPS, ("nx", "float")]
    columns = random_columns(props, 2)
    columns["nx"][0] = np.nan
    path = tmp_path / "nan-normal.ply"
    path.write_bytes(raw_ply(props, columns))
    assert np.isnan(read_ply(path).extras["nx"][0])


# -- atomic writes ----------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "bad",
    [np.zeros((3, 2), np.float32), np.array([None] * 3, dtype=object), np.zeros(3, np.int64), np.zeros(4, np.float32)],
    ids=["2d", "object", "int64", "wrong-length"],
)
def test_write_with_a_bad_extra_fails_and_keeps_the_old_file(tmp_path, bad):
    path = tmp_path / "out.ply"
    path.write_bytes(b"old")
    scene = make_scene(3, 0)
    scene.extras["bad"] = bad
    with pytest.raises(ValueError, match="bad"):
        write_ply(path, scene)
    assert path.read_bytes() == b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.ply"]


@pytest.mark.parametrize("name", ["x", "f_rest_4", "two words", ""])
def test_write_rejects_extra_names_that_cannot_be_written(tmp_path, name):
    scene = make_scene(2, 0)
    scene.extras[name] = np.zeros(2, np.float32)
    with pytest.raises(ValueError):
        write_ply(tmp_path / "out.ply", scene)
    assert list(tmp_path.iterdir()) == []


def test_failed_rename_removes_the_temp_file(tmp_path, monkeypatch):
    path = tmp_path / "out.ply"
    path.write_bytes(b"old")

    def fail(src, dst):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(ply.os, "replace", fail)
    with pytest.raises(OSError, match="No space"):
        write_ply(path, make_scene(5, 1))
    assert path.read_bytes() == b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.ply"]


def test_writing_onto_a_directory_fails_without_leftovers(tmp_path):
    (tmp_path / "target.ply").mkdir()
    with pytest.raises(OSError):
        write_ply(tmp_path / "target.ply", make_scene(2, 0))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["target.ply"]


def test_write_replaces_an_existing_file_with_normal_permissions(tmp_path):
    path = tmp_path / "out.ply"
    write_ply(path, make_scene(2, 0))
    umask = os.umask(0)
    os.umask(umask)
    assert path.stat().st_mode & 0o777 == 0o666 & ~umask
    write_ply(path, make_scene(3, 0))
    assert len(read_ply(path)) == 3
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.ply"]


# -- corrupted files never raise anything but PlyFormatError ----------------------------------------------


def _fuzz_bases() -> dict[str, bytes]:
    props = [(name, "float") for name in core_names(3)] + [("nx", "float"), ("c", "uchar"), ("d", "double")]
    columns = random_columns(props, 4, seed=4)
    face = (["element face 2", "property list uchar int idx"], struct.pack("<B2iB1i", 2, 0, 1, 1, 3))
    return {
        "binary": raw_ply(props, columns),
        "big": raw_ply(props, columns, "binary_big_endian"),
        "ascii": raw_ply(props, columns, "ascii"),
        "binary-face": raw_ply(props, columns, before=face),
        "ascii-face": raw_ply(props, columns, "ascii", before=(face[0], b"2 0 1\n1 3\n")),
    }


FUZZ_BASES = _fuzz_bases()
MUTATION = st.one_of(
    st.tuples(st.just("set"), st.integers(0, 10**6), st.integers(0, 255)),
    st.tuples(st.just("set-text"), st.integers(0, 10**6), st.sampled_from(b"0123456789-. \nenaif")),
    st.tuples(st.just("delete"), st.integers(0, 10**6), st.integers(1, 16)),
    st.tuples(st.just("insert"), st.integers(0, 10**6), st.binary(min_size=1, max_size=8)),
    st.tuples(st.just("truncate"), st.integers(0, 10**6), st.just(0)),
)


def mutate(data: bytes, mutations: list[tuple]) -> bytes:
    buffer = bytearray(data)
    for kind, position, arg in mutations:
        at = position % (len(buffer) + 1)
        if kind in ("set", "set-text") and at < len(buffer):
            buffer[at] = arg
        elif kind == "delete":
            del buffer[at : at + arg]
        elif kind == "insert":
            buffer[at:at] = arg
        elif kind == "truncate":
            del buffer[at:]
    return bytes(buffer)


@pytest.fixture(scope="module")
def fuzz_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("fuzz")


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    base=st.sampled_from(sorted(FUZZ_BASES)),
    mutations=st.lists(MUTATION, min_size=1, max_size=4),
    drop_invalid=st.booleans(),
)
def test_corrupted_files_load_or_raise_ply_format_error(fuzz_dir, base, mutations, drop_invalid):
    path = fuzz_dir / "corrupt.ply"
    path.write_bytes(mutate(FUZZ_BASES[base], mutations))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            scene = read_ply(path, drop_invalid=drop_invalid)
        except PlyFormatError as exc:
            assert str(path) in str(exc)
            scene = None
    assert all("dropped" in str(w.message) for w in caught), [str(w.message) for w in caught]
    if scene is not None:
        for key, tensor in scene.tensors().items():
            assert tensor.dtype == torch.float32 and bool(torch.isfinite(tensor).all()), key
