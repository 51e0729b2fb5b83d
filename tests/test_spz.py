"""Niantic SPZ: our reader on files PlayCanvas splat-transform wrote, splat-transform on files we wrote (the
oracle both ways), SH degrees 0-3, versions 2-4, renders, and every way a file can be broken.

Every tolerance is what one quantisation step of the format allows (see ``tolerances``), never what happens
to pass."""

from __future__ import annotations

import gzip
import importlib.util
import math
import struct
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from gt2gs_blender.core.cameras.generate import auto_views
from gt2gs_blender.core.errors import SplatFormatError
from gt2gs_blender.core.render import render
from gt2gs_blender.core.scene import codec
from gt2gs_blender.core.scene.arrays import SplatArrays
from gt2gs_blender.core.scene.codec import canonical_quats, colour_from_dc, sigmoid
from gt2gs_blender.core.scene.gaussians import GaussianScene
from gt2gs_blender.core.scene.inria import SH_C0
from gt2gs_blender.core.scene.ply import read_ply, read_ply_arrays
from gt2gs_blender.core.scene.ply_write import write_ply
from gt2gs_blender.core.scene.spz import read_spz, write_spz

from .splat_tools import donut_path, splat_transform, synthetic_scene

FLOAT_SLACK = 1e-5
"""float32 rounding of values of magnitude <= 15 on either side (1e-6 each), far below every step here."""
MIN_PSNR = 30.0
needs_zstd = pytest.mark.skipif(
    importlib.util.find_spec("zstandard") is None, reason="spz version 4 needs the zstandard package"
)


def tolerances(fractional_bits: int, version: int, sh_bits: tuple[int, int] = (5, 4)) -> dict[str, float]:
    """The largest error one SPZ round trip may leave in each field: half a quantisation step, plus float32
    rounding. ``colour`` is 0.5 + SH_C0 dc, ``opacity`` is sigmoid(logit), ``sh_band1``/``sh_rest`` are SH
    coefficients."""
    h3 = 0.5 * math.sqrt(0.5) / 511  # v3: the three stored components, 9 bits over 0..sqrt(1/2)
    h2 = 0.5 / 127.5  # v2: x, y, z, 8 bits over -1..1
    # The rebuilt component: with s = sum of squares of the stored ones, |s - s'| <= h (2 sum|v| + 3 h).
    # v3: the dropped largest l >= 1/2 and sum|v| <= sqrt(3) sqrt(1 - l^2) <= 3/2, so
    #     |l - l'| = |s - s'| / (l + l') <= 2 h (3 + 3 h).
    # v2: w = sqrt(1 - s) can be small; |w - w'| <= sqrt(|s - s'|) (sqrt is 1/2-Hoelder), sum|v| <= sqrt(3).
    rotation = 6 * h3 * (1 + h3) if version >= 3 else math.sqrt(h2 * (2 * math.sqrt(3) + 3 * h2))
    # SH: a byte v * 128 + 128 rounded (1/2), then to a multiple of 2^(8 - bits) (half of that).
    band1, rest = ((0.5 + (2 ** (8 - bits)) // 2) / 128 for bits in sh_bits)
    return {
        "position": 0.5 * 2.0**-fractional_bits,  # plus one float32 ulp of the largest position, in compare()
        "log_scale": 0.5 / 16 + FLOAT_SLACK,
        "colour": SH_C0 * 0.5 / (255 * 0.15) + FLOAT_SLACK,  # the DC byte is (0.5 + 0.15 dc) * 255
        "opacity": 0.5 / 255 + FLOAT_SLACK,
        "rotation": rotation + FLOAT_SLACK,
        "sh_band1": band1 + FLOAT_SLACK,
        "sh_rest": rest + FLOAT_SLACK,
    }


def errors(ours: SplatArrays, source: SplatArrays) -> dict[str, float]:
    """The largest error per field of a decoded scene against its source, clipped to SPZ's ranges."""
    dc = np.clip(source.sh_dc, -0.5 / 0.15, 0.5 / 0.15)
    log_scales = np.clip(source.log_scales, -10, 255 / 16 - 10)
    sh = np.clip(source.sh_rest, -1, 127 / 128)
    a, b = canonical_quats(ours.quats), canonical_quats(source.quats)
    rotation = np.minimum(np.abs(a - b).max(axis=1), np.abs(a + b).max(axis=1))  # q and -q: one rotation
    sh_error = np.abs(ours.sh_rest - sh)
    out = {
        "position": np.abs(ours.means - source.means).max(),
        "log_scale": np.abs(ours.log_scales - log_scales).max(),
        "colour": np.abs(colour_from_dc(ours.sh_dc) - colour_from_dc(dc)).max(),
        "opacity": np.abs(sigmoid(ours.opacity_logits) - sigmoid(source.opacity_logits)).max(),
        "rotation": rotation.max(),
    }
    if sh.shape[1]:
        out["sh_band1"] = sh_error[:, :3].max()
    if sh.shape[1] > 3:
        out["sh_rest"] = sh_error[:, 3:].max()
    return {key: float(value) for key, value in out.items()}


def compare(ours: SplatArrays, source: SplatArrays, fractional_bits: int, version: int, **kw) -> dict[str, float]:
    """Assert every field of ``ours`` is within one quantisation of ``source``; return the errors."""
    assert len(ours) == len(source) and ours.sh_rest.shape == source.sh_rest.shape
    limits = tolerances(fractional_bits, version, **kw)
    limits["position"] += 2.0**-23 * float(np.abs(source.means).max())
    measured = errors(ours, source)
    for key, value in measured.items():
        assert value <= limits[key], f"{key}: error {value:.3g} over the format's {limits[key]:.3g}"
    print({key: f"{value:.3g} (limit {limits[key]:.3g})" for key, value in measured.items()})
    return measured


def fractional_bits_of(path: Path) -> int:
    """The header's fractional bits (byte 13 in every version; inside the gzip stream for 2 and 3)."""
    data = path.read_bytes()
    return (gzip.decompress(data) if data[:2] == b"\x1f\x8b" else data)[13]


def assert_same_arrays(a: SplatArrays, b: SplatArrays, atol: float = 1e-6) -> None:
    """Every parameter of ``a`` within ``atol`` of ``b``'s (float32 rounding of one decoding)."""
    for key, value in a.tensors().items():
        np.testing.assert_allclose(value, b.tensors()[key], rtol=0, atol=atol, err_msg=key)


@pytest.fixture(scope="module")
def sources(tmp_path_factory) -> dict[str, Path]:
    """The shared donut (SH degree 0) and a synthetic SH degree 3 scene, as PLY files."""
    folder = tmp_path_factory.mktemp("spz_sources")
    write_ply(folder / "synthetic.ply", synthetic_scene(2000, sh_degree=3))
    return {"donut": donut_path(), "synthetic": folder / "synthetic.ply"}


@pytest.fixture(scope="module")
def theirs(sources, tmp_path_factory) -> dict[tuple[str, int], Path]:
    """splat-transform's .spz of each source, versions 3 and 4 (it writes no version 2)."""
    folder = tmp_path_factory.mktemp("spz_theirs")
    files = {}
    for name, ply in sources.items():
        for version in (3, 4):
            files[name, version] = folder / f"{name}_v{version}.spz"
            splat_transform(ply, "--spz-version", str(version), files[name, version])
    return files


@pytest.mark.parametrize("version", [3, pytest.param(4, marks=needs_zstd)])
@pytest.mark.parametrize("name", ["donut", "synthetic"])
def test_we_read_what_splat_transform_writes(name, version, sources, theirs, tmp_path):
    spz = theirs[name, version]
    ours = read_spz(spz)
    compare(ours, read_ply_arrays(sources[name]), fractional_bits_of(spz), version)
    splat_transform(spz, tmp_path / "back.ply")  # splat-transform's own decoding of its file
    assert_same_arrays(ours, read_ply_arrays(tmp_path / "back.ply"))


@needs_zstd
@pytest.mark.parametrize("name", ["donut", "synthetic"])
def test_versions_3_and_4_hold_the_same_values(name, theirs):
    assert_same_arrays(read_spz(theirs[name, 3]), read_spz(theirs[name, 4]), atol=0)


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("name", ["donut", "synthetic"])
def test_splat_transform_reads_what_we_write(name, version, sources, tmp_path):
    source = read_ply_arrays(sources[name])
    ours = tmp_path / "ours.spz"
    write_spz(ours, source, version=version)
    assert fractional_bits_of(ours) == 12
    splat_transform(ours, tmp_path / "back.ply")
    back = read_ply_arrays(tmp_path / "back.ply")
    compare(back, source, 12, version)
    assert_same_arrays(back, read_spz(ours))


@pytest.mark.parametrize("name", ["donut", "synthetic"])
def test_our_bytes_are_the_reference_writers(name, sources, theirs, tmp_path):
    """Same header and blocks as the reference packer; the few bytes that differ are values on a rounding
    tie that the reference, computing in float32, sends the other way."""
    write_spz(tmp_path / "ours.spz", read_ply_arrays(sources[name]))
    ours = np.frombuffer(gzip.decompress((tmp_path / "ours.spz").read_bytes()), np.uint8)
    reference = np.frombuffer(gzip.decompress(theirs[name, 3].read_bytes()), np.uint8)
    assert ours.shape == reference.shape
    assert np.array_equal(ours[:16], reference[:16])
    assert np.count_nonzero(ours != reference) <= 1e-4 * len(ours)


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("degree", [0, 1, 2, 3])
def test_every_sh_degree_round_trips(degree, version, tmp_path):
    source = synthetic_scene(300, sh_degree=degree, seed=degree)
    assert write_spz(tmp_path / "s.spz", source, version=version) == []
    compare(read_spz(tmp_path / "s.spz"), source, 12, version)
    write_spz(tmp_path / "fine.spz", source, version=version, fractional_bits=20, sh_bits=(8, 8))
    fine = compare(read_spz(tmp_path / "fine.spz"), source, 20, version, sh_bits=(8, 8))
    assert fine["position"] < 2.0**-20


def test_renders_match_the_ply(sources, theirs, tmp_path):
    reference = read_ply(sources["donut"])
    cameras = auto_views(reference, 4, width=128, height=128)
    expected = render(reference, cameras).colors.clamp(0, 1)
    write_spz(tmp_path / "ours.spz", read_ply_arrays(sources["donut"]))
    for spz in (theirs["donut", 3], tmp_path / "ours.spz"):
        arrays = read_spz(spz)
        scene = GaussianScene(**{key: torch.from_numpy(value) for key, value in arrays.tensors().items()})
        image = render(scene, cameras).colors.clamp(0, 1)
        psnr = float(10 * torch.log10(1.0 / torch.mean((image - expected) ** 2)))
        print(f"{spz.name}: PSNR {psnr:.1f} dB")
        assert psnr >= MIN_PSNR


def test_the_notes_name_what_the_file_loses(tmp_path):
    scene = synthetic_scene(100, sh_degree=1)
    scene.extras = {name: np.zeros(100, np.float32) for name in ("nx", "ny", "nz")}
    scene.sh_dc[0, 0], scene.sh_dc[1, 2] = 5.0, -4.0  # beyond +-0.5 / 0.15 (colour 1.9 and -0.6)
    scene.log_scales[0, 1], scene.log_scales[1, 0] = -12.0, 7.0  # beyond -10..(255 / 16 - 10)
    scene.sh_rest[0] = 1.5  # a point's 3 x 3 band 1 coefficients beyond 127 / 128
    notes = write_spz(tmp_path / "lossy.spz", scene)
    assert notes == [
        "spz keeps no extra properties: nx, ny, nz dropped",
        "spz clips DC colour coefficients to +-3.33 (colour -0.44..1.44): 2 values clipped",
        "spz clips log scales to -10..5.94: 2 values clipped",
        "spz clips SH band 1-3 coefficients to -1..0.99: 9 values clipped",
    ]
    back = read_spz(tmp_path / "lossy.spz")
    assert back.extras == {} and back.log_scales[0, 1] == -10.0 and back.log_scales[1, 0] == 255 / 16 - 10


def test_a_torch_scene_writes_the_same_bytes(tmp_path):
    arrays = synthetic_scene(200, sh_degree=2)
    scene = GaussianScene(**{key: torch.from_numpy(value) for key, value in arrays.tensors().items()})
    write_spz(tmp_path / "numpy.spz", arrays)
    write_spz(tmp_path / "torch.spz", scene)
    assert (tmp_path / "numpy.spz").read_bytes() == (tmp_path / "torch.spz").read_bytes()


def test_positions_keep_their_range_and_empty_scenes_work(tmp_path):
    far = synthetic_scene(50, sh_degree=0)
    far.means[0] = (3000.0, -5000.0, 1.0)  # beyond +-2048: 12 fractional bits would wrap
    write_spz(tmp_path / "far.spz", far)
    assert fractional_bits_of(tmp_path / "far.spz") == 10
    compare(read_spz(tmp_path / "far.spz"), far, 10, 3)
    empty = synthetic_scene(0, sh_degree=2)
    assert write_spz(tmp_path / "empty.spz", empty) == []
    back = read_spz(tmp_path / "empty.spz")
    assert len(back) == 0 and back.sh_rest.shape == (0, 8, 3)


def test_scenes_spz_cannot_hold_are_refused(tmp_path):
    scene = synthetic_scene(20, sh_degree=0)
    out = tmp_path / "x.spz"
    with pytest.raises(ValueError, match="version 4 is read only"):
        write_spz(out, scene, version=4)
    with pytest.raises(ValueError, match="fractional_bits=24 cannot hold"):
        write_spz(out, scene, fractional_bits=24)  # positions up to 1: 2^24 is beyond 24-bit integers
    scene.means[0, 0] = 1e7
    with pytest.raises(SplatFormatError, match=r"x\.spz: positions reach 1e\+07, beyond the"):
        write_spz(out, scene)
    scene.means[0, 0] = np.nan
    with pytest.raises(SplatFormatError, match=r"x\.spz: 1 of 20 Gaussians have NaN or Inf"):  # NaN: refused
        write_spz(out, scene)
    assert not out.exists() and list(tmp_path.iterdir()) == []


# Broken files: each one error naming the file.


@pytest.fixture
def payload(tmp_path) -> bytes:
    """A small version 3 file's decompressed bytes (10 points, SH degree 1: 16 + 10 * 29 bytes)."""
    write_spz(tmp_path / "good.spz", synthetic_scene(10, sh_degree=1))
    return gzip.decompress((tmp_path / "good.spz").read_bytes())


def broken(tmp_path: Path, data: bytes, compress: bool = True) -> Path:
    path = tmp_path / "broken.spz"
    path.write_bytes(gzip.compress(data) if compress else data)
    return path


def header(payload: bytes, **fields: int) -> bytes:
    """``payload`` with header fields replaced."""
    names = ("magic", "version", "count", "sh_degree", "fractional_bits", "flags", "reserved")
    values = dict(zip(names, struct.unpack_from("<IIIBBBB", payload)))
    values.update(fields)
    return struct.pack("<IIIBBBB", *values.values()) + payload[16:]


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda p: p[:100], r"truncated: the header promises 10 points \(290 bytes of data\) but only 84"),
        (lambda p: p[:10], "truncated: 10 bytes, less than the 16-byte spz header"),
        (lambda p: header(p, magic=0x12345678), "not an spz file .magic 0x12345678"),
        (lambda p: header(p, version=5), "unsupported spz version 5"),
        (lambda p: header(p, version=1), "unsupported spz version 1"),
        (lambda p: header(p, count=11), "truncated: the header promises 11 points .319 bytes of data. but only 290"),
        (lambda p: header(p, count=9), "more data than the 261 bytes that the header's 9 points need"),
        (lambda p: header(p, sh_degree=4), "SH degree 4 is not supported"),
    ],
)
def test_broken_payloads_are_one_error_naming_the_file(change, message, payload, tmp_path):
    with pytest.raises(SplatFormatError, match=rf"broken\.spz: {message}"):
        read_spz(broken(tmp_path, change(payload)))


def test_broken_containers_are_one_error_naming_the_file(payload, tmp_path, monkeypatch):
    whole = gzip.compress(payload)
    with pytest.raises(SplatFormatError, match=r"broken\.spz: the gzip stream is corrupt or truncated"):
        read_spz(broken(tmp_path, whole[: len(whole) // 2], compress=False))
    with pytest.raises(SplatFormatError, match=r"broken\.spz: not an spz file \(neither a gzip stream"):
        read_spz(broken(tmp_path, b"PK\x03\x04 a zip, not an spz", compress=False))
    with pytest.raises(SplatFormatError, match=r"missing\.spz: cannot read the file"):
        read_spz(tmp_path / "missing.spz")
    monkeypatch.setattr(codec, "DECODE_FLOOR", 2**20)  # a 2 KiB gzip declaring 2 MiB: a bomb under this floor
    with pytest.raises(SplatFormatError, match=r"broken\.spz: declares \d+ bytes uncompressed \(70000 points"):
        read_spz(broken(tmp_path, header(payload, count=70000) + bytes(2 * 2**20)))


def test_a_flagged_extension_may_follow_and_antialiasing_is_a_warning(payload, tmp_path):
    read_spz(broken(tmp_path, header(payload, flags=2) + b"extension record"))
    with pytest.warns(UserWarning, match=r"broken\.spz: trained with antialiasing"):
        read_spz(broken(tmp_path, header(payload, flags=1)))


@needs_zstd
def test_broken_version_4_files_are_one_error_naming_the_file(theirs, tmp_path, monkeypatch):
    good = theirs["synthetic", 4].read_bytes()
    n_streams, toc = struct.unpack_from("<BI", good, 15)
    alphas = toc + 16 * n_streams + int(np.frombuffer(good, "<u8", 1, toc)[0])  # after the positions stream
    cases = {
        "truncated: the sh stream ends beyond the end of the file": good[:-10],
        "truncated: 20 bytes, less than the 32-byte spz header": good[:20],
        "unsupported spz version 5": good[:4] + struct.pack("<I", 5) + good[8:],
        "the positions stream holds 18000 bytes, not the 17991 of the header's 1999 points": (
            good[:8] + struct.pack("<I", 1999) + good[12:]
        ),
        "5 data streams, expected 6 for SH degree 3": good[:15] + bytes([5]) + good[16:],
        "the alphas stream is corrupt": good[:alphas] + b"garbage!" + good[alphas + 8 :],
    }
    for message, data in cases.items():
        with pytest.raises(SplatFormatError, match=rf"broken\.spz: {message}"):
            read_spz(broken(tmp_path, data, compress=False))
    monkeypatch.setitem(sys.modules, "zstandard", None)  # as where the package is not installed
    with pytest.raises(SplatFormatError, match=r"broken\.spz: spz version 4 is zstd-compressed and needs"):
        read_spz(broken(tmp_path, good, compress=False))
