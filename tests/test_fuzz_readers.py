"""Fuzzing every splat reader and writer: random bytes, truncations and field mutations of real files in every
format (small files our writers made, files splat-transform made, a shared capture) either read as finite
float32 arrays or raise the project's one-line error naming the file; extreme-but-finite scenes written in
every format read back or are refused naming the output; and decompression bombs are refused from their
headers, under a memory limit, in a fraction of a second.

Hypothesis runs a fixed number of derandomised examples, so CI sees the same inputs every run.
"""

from __future__ import annotations

import gzip
import io
import json
import os
import struct
import subprocess
import sys
import warnings
import zipfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gt2gs_blender.core.errors import InputFileError
from gt2gs_blender.core.scene.files import COMPRESSED_PLY, PLY, READERS, SOG, SPLAT, SPZ, WRITERS, write_splats

from .splat_tools import ROOT, SPLAT_TRANSFORM, splat_transform, synthetic_scene

CAPTURE = ROOT.parent / "shared" / "data" / "scenes" / "captures" / "guitar.compressed.ply"
ENDINGS = {PLY: ".ply", COMPRESSED_PLY: ".compressed.ply", SOG: ".sog", SPZ: ".spz", SPLAT: ".splat"}
FUZZ = settings(
    max_examples=300,
    derandomize=True,
    deadline=2000,
    database=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
pytestmark = pytest.mark.timeout(180)


@pytest.fixture(scope="module")
def real_files(tmp_path_factory) -> dict[str, bytes]:
    """Small real files by name: ours in every writable format (SH degrees 0 and 3, spz versions 2 and 3),
    splat-transform's SOG and spz version 4 when it is installed, and a slice of a shared capture."""
    folder = tmp_path_factory.mktemp("fuzz_sources")
    files = {}
    for degree in (0, 3):
        scene = synthetic_scene(300, sh_degree=degree, seed=degree)
        for fmt in WRITERS:
            files[f"ours_d{degree}{ENDINGS[fmt]}"] = folder / f"ours_d{degree}{ENDINGS[fmt]}"
            write_splats(files[f"ours_d{degree}{ENDINGS[fmt]}"], scene, fmt)
    from gt2gs_blender.core.scene.spz import write_spz

    write_spz(folder / "ours_v2.spz", synthetic_scene(300, sh_degree=1), version=2)
    files["ours_v2.spz"] = folder / "ours_v2.spz"
    if SPLAT_TRANSFORM.is_file():
        for name, args in {"theirs.sog": ("-g", "cpu"), "theirs_v4.spz": ("--spz-version", "4")}.items():
            splat_transform(*args, files["ours_d3.ply"], folder / name)
            files[name] = folder / name
    if CAPTURE.is_file():
        files["guitar.compressed.ply"] = CAPTURE
    return {name: path.read_bytes() for name, path in files.items()}


def assert_reads_or_refuses(path: Path) -> None:
    """The file reads as finite float32 arrays, or the reader for its name raises one line naming it."""
    fmt = next((f for f, ending in ENDINGS.items() if path.name.endswith(ending) and f != PLY), PLY)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # the readers' own notes (antialiasing, dropped splats)
            warnings.simplefilter("error", RuntimeWarning)  # numpy's overflow warnings are stray lines for a user
            arrays = READERS[fmt](path)
    except InputFileError as exc:
        assert str(path) in str(exc) and "\n" not in str(exc), str(exc)
        return
    for name, values in arrays.tensors().items():
        assert values.dtype == np.float32 and np.isfinite(values).all(), name


def place(tmp_path: Path, name: str, data: bytes) -> Path:
    path = tmp_path / name
    path.write_bytes(data)
    return path


@FUZZ
@given(st.data())
def test_random_truncations_read_or_are_refused(real_files, tmp_path, data):
    name = data.draw(st.sampled_from(sorted(real_files)))
    whole = real_files[name]
    cut = data.draw(st.integers(0, len(whole) - 1) | st.integers(0, min(len(whole) - 1, 600)))
    assert_reads_or_refuses(place(tmp_path, name, whole[:cut]))


@FUZZ
@given(st.data())
def test_random_byte_mutations_read_or_are_refused(real_files, tmp_path, data):
    name = data.draw(st.sampled_from(sorted(real_files)))
    whole = bytearray(real_files[name])
    for _ in range(data.draw(st.integers(1, 8))):
        at = data.draw(st.integers(0, min(len(whole) - 1, 1500)) | st.integers(0, len(whole) - 1))
        whole[at] = data.draw(st.sampled_from([0, 1, 0x7F, 0x80, 0xFF]) | st.integers(0, 255))
    assert_reads_or_refuses(place(tmp_path, name, bytes(whole)))


@FUZZ
@given(st.sampled_from(sorted(ENDINGS.values())), st.binary(max_size=400), st.sampled_from([b"", b"ply\n"]))
def test_random_bytes_read_or_are_refused(tmp_path, ending, body, prefix):
    assert_reads_or_refuses(place(tmp_path, f"random{ending}", prefix + body))


SPZ_FIELDS = {"count": (8, "<I"), "sh_degree": (12, "<B"), "fractional_bits": (13, "<B"), "flags": (14, "<B")}


@FUZZ
@given(st.data())
def test_mutated_spz_headers_read_or_are_refused(real_files, tmp_path, data):
    """Header fields of a gzip spz changed inside the stream (so the gzip check passes), then recompressed."""
    name = data.draw(st.sampled_from([n for n in sorted(real_files) if n.endswith(".spz") and "v4" not in n]))
    payload = bytearray(gzip.decompress(real_files[name]))
    field = data.draw(st.sampled_from(sorted(SPZ_FIELDS)))
    offset, code = SPZ_FIELDS[field]
    top = 2 ** (8 * struct.calcsize(code)) - 1
    struct.pack_into(code, payload, offset, data.draw(st.integers(0, top) | st.sampled_from([0, 1, top])))
    assert_reads_or_refuses(place(tmp_path, name, gzip.compress(bytes(payload), compresslevel=1)))


JSON = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=8),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner, max_size=4),
    max_leaves=10,
)


def rezip(source: bytes, replace: dict[str, bytes]) -> bytes:
    """A SOG zip with some entries replaced."""
    out = io.BytesIO()
    with zipfile.ZipFile(io.BytesIO(source)) as old, zipfile.ZipFile(out, "w") as new:
        for item in old.infolist():
            new.writestr(item.filename, replace.get(item.filename, old.read(item)))
    return out.getvalue()


@FUZZ
@given(st.data())
def test_mutated_sog_meta_json_and_images_read_or_are_refused(real_files, tmp_path, data):
    if "theirs.sog" not in real_files:
        pytest.skip(f"splat-transform is not installed at {SPLAT_TRANSFORM}: run `npm ci`")
    source = real_files["theirs.sog"]
    with zipfile.ZipFile(io.BytesIO(source)) as archive:
        meta = json.loads(archive.read("meta.json"))
        images = sorted(n for n in archive.namelist() if n.endswith(".webp"))
        image_name = data.draw(st.sampled_from(images))
        image = bytearray(archive.read(image_name))
    if data.draw(st.booleans()):
        section = data.draw(st.sampled_from(sorted(meta)))
        if isinstance(meta[section], dict) and meta[section] and data.draw(st.booleans()):
            meta[section][data.draw(st.sampled_from(sorted(meta[section])))] = data.draw(JSON)
        else:
            meta[section] = data.draw(JSON)
        replace = {"meta.json": json.dumps(meta).encode()}
    else:
        for _ in range(data.draw(st.integers(1, 4))):
            image[data.draw(st.integers(0, min(len(image) - 1, 40)))] = data.draw(st.integers(0, 255))
        replace = {image_name: bytes(image)}
    assert_reads_or_refuses(place(tmp_path, "mutated.sog", rezip(source, replace)))


# -- writers: extreme-but-finite scenes in every format read back or are refused naming the output ----------

F32 = float(np.finfo(np.float32).max)
EXTREMES = st.sampled_from([0.0, 1e-45, -1e-45, 1e-38, 1e30, -1e30, 3e38, -3e38, F32, -F32, 89.0, 100.0, -200.0, -1e3])


@settings(FUZZ, max_examples=40)
@given(
    st.sampled_from(["means", "quats", "log_scales", "opacity_logits", "sh_dc", "sh_rest"]),
    st.lists(EXTREMES, min_size=1, max_size=4),
    st.sampled_from(sorted(WRITERS)),
)
def test_extreme_values_written_in_every_format_read_back_or_are_refused(tmp_path, field, values, fmt):
    scene = synthetic_scene(260, sh_degree=1, seed=3)
    column = getattr(scene, field).reshape(260, -1)
    for i, value in enumerate(values):
        column[(37 * i) % 260, i % column.shape[1]] = value
    if field == "quats":
        scene.quats[5] = values[0]  # a zero or denormal quaternion: all four components
    path = tmp_path / f"out{ENDINGS[fmt]}"
    path.unlink(missing_ok=True)  # hypothesis runs every example in one tmp_path
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", RuntimeWarning)
            write_splats(path, scene, fmt)
    except InputFileError as exc:
        assert str(exc).startswith(f"{path}: ") and "\n" not in str(exc) and not path.exists()
        return
    back = READERS[fmt](path)
    assert len(back) == len(scene)
    for name, array in back.tensors().items():
        assert np.isfinite(array).all(), name


def test_a_splat_writer_clamps_scales_float32_cannot_hold_with_a_note(tmp_path):
    scene = synthetic_scene(4, sh_degree=0)
    scene.log_scales[:, 0] = [-200.0, -1000.0, 89.0, 100.0]
    notes = write_splats(tmp_path / "x.splat", scene)
    assert notes == ["splat clamps log scales to -87.3..88.7 (float32 scales): 4 values clamped"]
    back = READERS[SPLAT](tmp_path / "x.splat")
    np.testing.assert_allclose(back.log_scales[:, 0], [-87.34, -87.34, 88.72, 88.72], atol=0.01)


# -- decompression bombs, under a memory limit ---------------------------------------------------------------

BOMB_READER = """
import resource, sys, time
resource.setrlimit(resource.RLIMIT_AS, (2 * 2**30, 2 * 2**30))
from gt2gs_blender.core.errors import SplatFormatError
from gt2gs_blender.core.scene.files import read_splats
start = time.perf_counter()
try:
    read_splats(sys.argv[1])
except SplatFormatError as exc:
    print(f"{time.perf_counter() - start:.3f} {exc}")
"""


def vp8l_header(width: int, height: int) -> bytes:
    """The first bytes of a lossless WebP declaring ``width`` x ``height`` pixels (no image data)."""
    bits = (width - 1) | ((height - 1) << 14)
    chunk = b"VP8L" + struct.pack("<I", 5) + b"\x2f" + struct.pack("<I", bits)
    return b"RIFF" + struct.pack("<I", 4 + len(chunk)) + b"WEBP" + chunk


def sog_bomb(path: Path) -> Path:
    """A small SOG whose five images each declare 16383 x 16383 pixels (5 GiB of RGBA)."""
    names = ["means_l.webp", "means_u.webp", "quats.webp", "scales.webp", "sh0.webp"]
    codebook = list(np.linspace(-1, 1, 256))
    meta = {
        "version": 2,
        "count": 16383 * 16383,
        "means": {"mins": [0, 0, 0], "maxs": [1, 1, 1], "files": names[:2]},
        "quats": {"files": [names[2]]},
        "scales": {"codebook": codebook, "files": [names[3]]},
        "sh0": {"codebook": codebook, "files": [names[4]]},
    }
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr("meta.json", json.dumps(meta))
        for name in names:
            archive.writestr(name, vp8l_header(16383, 16383) + bytes(2000))
    return path


def spz_bomb(path: Path, count: int) -> Path:
    """A gzip spz whose header declares ``count`` SH degree 3 points, followed by 8 MiB of zeros."""
    header = struct.pack("<IIIBBBB", 0x5053474E, 3, count, 3, 12, 0, 0)
    path.write_bytes(gzip.compress(header + bytes(8 * 2**20), compresslevel=9))
    return path


def spz_v4_bomb(path: Path) -> Path:
    """A version 4 spz header declaring 2^32 - 1 points of SH degree 3."""
    path.write_bytes(struct.pack("<IIIBBBBI12x", 0x5053474E, 4, 2**32 - 1, 3, 12, 0, 6, 32) + bytes(200))
    return path


BOMBS = [
    (lambda folder: sog_bomb(folder / "bomb.sog"), "meta.json: declares 5368053780 bytes uncompressed"),
    (lambda folder: spz_bomb(folder / "bomb.spz", 2**32 - 1), "(4294967295 points of SH degree 3)"),
    (lambda folder: spz_bomb(folder / "mid.spz", 3_000_000), "(3000000 points of SH degree 3)"),
    (lambda folder: spz_v4_bomb(folder / "v4.spz"), "(4294967295 points of SH degree 3)"),
]
"""(make the file in a folder, what its one-line refusal says): SOG WebP headers, SPZ counts, an SPZ v4 count."""
BOMB_IDS = ["sog-webp-headers", "spz-huge-count", "spz-count-beyond-the-ratio", "spz-v4-count"]


@pytest.mark.parametrize(("make", "fragment"), BOMBS, ids=BOMB_IDS)
def test_decompression_bombs_are_refused_from_their_headers_under_a_memory_limit(tmp_path, make, fragment):
    path = make(tmp_path)
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    result = subprocess.run(
        [sys.executable, "-c", BOMB_READER, str(path)], capture_output=True, text=True, timeout=60, env=env
    )
    assert result.returncode == 0 and result.stderr == "", result.stderr
    seconds, message = result.stdout.strip().split(" ", 1)
    assert float(seconds) < 2.0 and message.startswith(f"{path}: ") and fragment in message, message


def test_a_sog_zip_asking_for_a_zip_version_python_lacks_is_refused_in_one_line(tmp_path):
    """A central directory whose entry needs zip version 12.7 to extract (hypothesis found one on Python 3.13, where
    zipfile raises NotImplementedError on opening): the one-line error naming the file, not a traceback."""
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as archive:
        archive.writestr("meta.json", "{}")
    data = bytearray(buffer.getvalue())
    entry = data.index(b"PK\x01\x02")  # the central directory's record of meta.json
    struct.pack_into("<H", data, entry + 6, 127)  # version needed to extract: 12.7
    path = place(tmp_path, "future.sog", bytes(data))
    with pytest.raises(InputFileError) as refused:
        READERS[SOG](path)
    assert str(path) in str(refused.value) and "\n" not in str(refused.value)
