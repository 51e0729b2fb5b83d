"""Tests of PlayCanvas compressed PLY reading and writing (gt2gs_blender.core.scene.compressed_ply).

The oracle is PlayCanvas splat-transform (tests/splat_tools.py). Its writer sorts splats in Morton
order, so our read of its files is matched to the source splat by splat (nearest positions, then the
candidate that fits every field best); our writer keeps the scene's order, and splat-transform's PLY
of our file is compared row by row. Every field must be within its quantisation step, derived from
the chunk ranges that the file holds (read here with plain numpy, not with the module).
"""

from __future__ import annotations

import math
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
import torch

from gt2gs_blender.core.errors import SplatFormatError
from gt2gs_blender.core.scene.arrays import SplatArrays
from gt2gs_blender.core.scene.codec import canonical_quats, sigmoid
from gt2gs_blender.core.scene.compressed_ply import is_compressed_ply, read_compressed_ply, write_compressed_ply
from gt2gs_blender.core.scene.gaussians import GaussianScene
from gt2gs_blender.core.scene.inria import SH_C0
from gt2gs_blender.core.scene.ply import read_ply_arrays
from gt2gs_blender.core.scene.ply_header import read_ply_header
from gt2gs_blender.core.scene.ply_write import write_ply

from .splat_tools import ROOT, donut_path, splat_transform, synthetic_scene

CHUNK = 256
EPS32 = float(np.finfo(np.float32).eps)
ROTATION_STEP = math.sqrt(2.0) / 1023
"""A stored quaternion component is (q / 1023 - 0.5) * sqrt 2: one step of q is sqrt 2 / 1023."""
SH_STEP = 8.0 / 256
"""A SH byte b stands for 8 ((b + 0.5) / 256 - 0.5): one step is 1/32."""
MEASURED: dict[str, dict[str, float]] = {}
"""Largest error and its tolerance per case and field (printed with ``pytest -s``; quoted in reports)."""


def _scene(name: str) -> SplatArrays:
    """The donut (SH degree 0) or a synthetic SH degree 3 scene of 2000 splats (8 chunks, the last partial)."""
    return read_ply_arrays(donut_path()) if name == "donut" else synthetic_scene(2000, 3)


def _raw_layout(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """The chunk ranges (C, 18 floats) and the packed vertex words (N, 4) of a compressed PLY, read with
    numpy from the layout splat-transform writes (chunk element first, 18 floats, then 4 uints)."""
    header = read_ply_header(path)
    chunk, vertex = header.elements[0], header.elements[1]
    assert chunk.name == "chunk" and len(chunk.properties) == 18
    assert vertex.name == "vertex" and len(vertex.properties) == 4
    data = path.read_bytes()
    ranges = np.frombuffer(data, "<f4", chunk.count * 18, header.header_size).reshape(-1, 18)
    words = np.frombuffer(data, "<u4", vertex.count * 4, header.header_size + ranges.nbytes)
    return ranges.astype(np.float64), words.reshape(-1, 4)


def _range_tolerance(lo: np.ndarray, hi: np.ndarray, steps: np.ndarray | float) -> np.ndarray:
    """Largest error of a value quantised to ``steps`` equal parts of [lo, hi]: half a step, as values
    round to the nearest step; a range under 1e-5 stores its minimum (error <= its width); plus a few
    float32 roundings of values of the range's size."""
    span = hi - lo
    quantised = np.where(span < 1e-5, span, 0.5 * span / steps)
    return quantised + 4 * EPS32 * np.maximum(np.abs(lo), np.abs(hi)) + 1e-12


def _tolerances(ranges: np.ndarray, n: int, k: int) -> dict[str, np.ndarray]:
    """Per-splat tolerances from each splat's chunk ranges (splat i is in chunk i // 256)."""
    r = ranges[np.arange(n) // CHUNK]
    bits_11_10_11 = np.array([2047.0, 1023.0, 2047.0])
    return {
        "means": _range_tolerance(r[:, 0:3], r[:, 3:6], bits_11_10_11),
        "log_scales": _range_tolerance(r[:, 6:9], r[:, 9:12], bits_11_10_11),
        # 8-bit colours over the chunk's colour range; DC = (colour - 0.5) / SH_C0 scales the error
        "sh_dc": _range_tolerance(r[:, 12:15], r[:, 15:18], 255.0) / SH_C0 + 1e-5,
        # activated opacity in 8 bits over 0..1: half of 1/255 (0 and 1 read as logits of +-13.8: 1e-6 off)
        "opacity": np.full(n, 0.5 / 255 + 2e-6),
        # the three stored components are off by half a step; the rebuilt largest one, sqrt(1 - |a|^2)
        # with |a| <= sqrt 3 / 2 and itself >= 1/2, by at most |a| |da| / m <= 3 half steps
        "quats": np.full((n, 4), 3 * 0.5 * ROTATION_STEP + 1e-6),
        # half a step inside [-4, 4] (the scenes here keep their SH inside)
        "sh_rest": np.full((n, k, 3), 0.5 * SH_STEP + 1e-6),
    }


def _errors(decoded: SplatArrays, source: SplatArrays, index: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Absolute errors per field of ``decoded`` against ``source`` (rows ``index`` of it, if given):
    opacity activated, quaternions normalised and up to sign."""
    pick = (lambda a: a) if index is None else (lambda a: a[index])
    q, q_source = canonical_quats(decoded.quats), canonical_quats(pick(source.quats))
    quat_error = np.minimum(np.abs(q - q_source).max(1), np.abs(q + q_source).max(1))
    return {
        "means": np.abs(decoded.means - pick(source.means)),
        "log_scales": np.abs(decoded.log_scales - pick(source.log_scales)),
        "sh_dc": np.abs(decoded.sh_dc - pick(source.sh_dc)),
        "opacity": np.abs(sigmoid(decoded.opacity_logits) - sigmoid(pick(source.opacity_logits))),
        "quats": np.repeat(quat_error[:, None], 4, 1),
        "sh_rest": np.abs(decoded.sh_rest - pick(source.sh_rest)),
    }


def _assert_within(case: str, errors: dict[str, np.ndarray], tolerances: dict[str, np.ndarray]) -> None:
    """Every error is within its splat's tolerance; records the largest error and tolerance per field."""
    MEASURED[case] = {}
    for key, error in errors.items():
        if error.size == 0:
            continue
        excess = error - tolerances[key]
        worst = np.unravel_index(int(np.argmax(excess)), error.shape)
        MEASURED[case][key] = (float(error.max()), float(tolerances[key].max()))
        assert excess[worst] <= 0.0, (
            f"{case}: {key} error {error[worst]:.3g} > tolerance {tolerances[key][worst]:.3g} at {worst}"
        )
    print(case, {key: f"max {e:.3g} (tolerance up to {t:.3g})" for key, (e, t) in MEASURED[case].items()})


def _match(decoded: SplatArrays, source: SplatArrays, tolerances: dict[str, np.ndarray]) -> np.ndarray:
    """For each decoded splat, the source splat it came from: of its 8 nearest source positions, the one
    whose worst field error relative to its tolerance is smallest. Checked to be a permutation."""
    means = torch.from_numpy(source.means.astype(np.float64))
    candidates = []
    for start in range(0, len(decoded), 1024):
        query = torch.from_numpy(decoded.means[start : start + 1024].astype(np.float64))
        k = min(8, len(source))
        candidates.append(torch.cdist(query, means).topk(k, largest=False).indices.numpy())
    candidates = np.concatenate(candidates)
    scores = np.empty(candidates.shape)
    for j in range(candidates.shape[1]):
        errors = _errors(decoded, source, candidates[:, j])
        scores[:, j] = np.max(
            [(errors[key] / tolerances[key]).reshape(len(decoded), -1).max(1) for key in errors if errors[key].size],
            axis=0,
        )
    match = candidates[np.arange(len(decoded)), np.argmin(scores, 1)]
    assert len(np.unique(match)) == len(source) == len(decoded), "the decoded splats do not map one to one"
    return match


def _convert(source: Path, target: Path) -> None:
    splat_transform(source, target)
    assert target.is_file()


@pytest.mark.parametrize("name", ["donut", "synthetic"])
def test_reads_what_splat_transform_writes(name, tmp_path):
    source = _scene(name)
    ply, compressed = tmp_path / "source.ply", tmp_path / "scene.compressed.ply"
    write_ply(ply, source)
    _convert(ply, compressed)
    assert is_compressed_ply(read_ply_header(compressed))
    decoded = read_compressed_ply(compressed)
    assert len(decoded) == len(source) and decoded.sh_rest.shape[1:] == source.sh_rest.shape[1:]
    ranges, _ = _raw_layout(compressed)
    tolerances = _tolerances(ranges, len(source), source.sh_rest.shape[1])
    match = _match(decoded, source, tolerances)  # splat-transform wrote them in Morton order
    assert not np.array_equal(match, np.arange(len(source))), "expected splat-transform to reorder the splats"
    _assert_within(f"read splat-transform {name}", _errors(decoded, source, match), tolerances)


@pytest.mark.parametrize("name", ["donut", "synthetic"])
def test_splat_transform_reads_what_we_write(name, tmp_path):
    source = _scene(name)
    compressed, back = tmp_path / "ours.compressed.ply", tmp_path / "back.ply"
    assert write_compressed_ply(compressed, source) == []
    _convert(compressed, back)
    ranges, words = _raw_layout(compressed)
    # splat-transform reads opacity bytes 0 and 255 as logits of -inf and +inf (our reader: +-13.8), which
    # the PLY reader refuses: those rows are dropped here, and only those (the donut has 930 of them).
    extreme = np.isin(words[:, 3] & 0xFF, (0, 255))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        decoded = read_ply_arrays(back, drop_invalid=True)
    assert len(decoded) == int((~extreme).sum())
    kept = np.flatnonzero(~extreme)
    tolerances = _tolerances(ranges, len(source), source.sh_rest.shape[1])
    tolerances = {key: value[kept] for key, value in tolerances.items()}
    _assert_within(f"splat-transform reads ours {name}", _errors(decoded, source, kept), tolerances)
    ours = read_compressed_ply(compressed)  # and our reader, in the same (input) order, on every splat
    _assert_within(
        f"round trip {name}", _errors(ours, source), _tolerances(ranges, len(source), source.sh_rest.shape[1])
    )


@pytest.mark.parametrize(("n", "degree"), [(0, 0), (1, 1), (300, 2), (513, 3), (256, 0)])
def test_round_trip_in_order(n, degree, tmp_path):
    source = synthetic_scene(n, degree, seed=n)
    path = tmp_path / "scene.compressed.ply"
    write_compressed_ply(path, source)
    decoded = read_compressed_ply(path)
    assert decoded.sh_rest.shape == source.sh_rest.shape and decoded.means.dtype == np.float32
    ranges, _ = _raw_layout(path)
    assert len(ranges) == -(-n // CHUNK)
    tolerances = _tolerances(ranges, n, source.sh_rest.shape[1])
    _assert_within(f"round trip n={n} degree={degree}", _errors(decoded, source), tolerances)


def _psnr(a: torch.Tensor, b: torch.Tensor) -> float:
    mse = float(torch.mean((a - b) ** 2))
    return 10 * math.log10(1.0 / max(mse, 1e-12))


def test_render_matches_the_ply(tmp_path):
    from gt2gs_blender.core.cameras.generate import auto_views
    from gt2gs_blender.core.render import render

    def scene(arrays: SplatArrays) -> GaussianScene:
        return GaussianScene(**{k: torch.from_numpy(v) for k, v in arrays.tensors().items()})

    source = read_ply_arrays(donut_path())
    theirs, ours = tmp_path / "theirs.compressed.ply", tmp_path / "ours.compressed.ply"
    _convert(donut_path(), theirs)
    write_compressed_ply(ours, source)
    cameras = auto_views(scene(source), 4, width=128, height=128)
    reference = render(scene(source), cameras, render_depth=False).colors
    for label, path in (("splat-transform's file", theirs), ("our file", ours)):
        images = render(scene(read_compressed_ply(path)), cameras, render_depth=False).colors
        psnrs = [_psnr(a, b) for a, b in zip(images, reference)]
        print(f"donut PSNR, {label}: {', '.join(f'{p:.1f}' for p in psnrs)} dB")
        assert min(psnrs) >= 30.0, f"{label}: PSNR {min(psnrs):.1f} dB < 30"


# --- bad input -------------------------------------------------------------------------------------


@pytest.fixture
def good_file(tmp_path) -> Path:
    """A compressed PLY of 600 splats (3 chunks) and SH degree 1, written by our writer."""
    path = tmp_path / "good.compressed.ply"
    write_compressed_ply(path, synthetic_scene(600, 1))
    return path


def _edit_header(path: Path, old: bytes, new: bytes) -> None:
    data = path.read_bytes()
    assert len(old) == len(new) and data.count(old) == 1
    path.write_bytes(data.replace(old, new))


def _expect_error(path: Path, words: str) -> SplatFormatError:
    with pytest.raises(SplatFormatError) as info:
        read_compressed_ply(path)
    message = str(info.value)
    assert message.startswith(str(path)) and "\n" not in message and words in message, message
    return info.value


def test_truncated(good_file):
    data = good_file.read_bytes()
    good_file.write_bytes(data[:-100])
    _expect_error(good_file, "truncated")
    good_file.write_bytes(data[: read_ply_header(good_file).header_size + 10])
    _expect_error(good_file, "truncated")


def test_chunk_count_mismatch(good_file):
    _edit_header(good_file, b"element chunk 3\n", b"element chunk 4\n")
    _expect_error(good_file, "4 chunks for 600 splats")


def test_missing_packed_property(good_file):
    _edit_header(good_file, b"packed_scale", b"packed_sxale")
    _expect_error(good_file, "packed_scale")


def test_nan_in_a_chunk_range(good_file):
    header_size = read_ply_header(good_file).header_size
    data = bytearray(good_file.read_bytes())
    data[header_size + 18 * 4 + 4 * 4 : header_size + 18 * 4 + 5 * 4] = np.float32(np.nan).tobytes()  # chunk 1 max_y
    good_file.write_bytes(bytes(data))
    _expect_error(good_file, "NaN or Inf ranges (chunk 1)")
    with pytest.warns(UserWarning, match="dropped 256 of 600"):
        kept = read_compressed_ply(good_file, drop_invalid=True)
    assert len(kept) == 600 - 256


def test_not_compressed(tmp_path):
    plain = tmp_path / "plain.ply"
    write_ply(plain, synthetic_scene(10, 0))
    assert not is_compressed_ply(read_ply_header(plain))
    _expect_error(plain, "no 'chunk' element")
    junk = tmp_path / "junk.compressed.ply"
    junk.write_bytes(b"not a ply at all")
    _expect_error(junk, "not a PLY file")
    _expect_error(tmp_path / "missing.compressed.ply", "cannot read")


def test_sh_element_must_fit(good_file):
    _edit_header(good_file, b"element sh 600\n", b"element sh 601\n")
    _expect_error(good_file, "'sh' element has 601 rows")


# --- writer -------------------------------------------------------------------------------------------


def test_writer_notes_what_it_drops(tmp_path):
    source = synthetic_scene(50, 1)
    source.extras = {"nx": np.zeros(50, np.float32), "label": np.arange(50, dtype=np.int32)}
    source.sh_rest[0, 0, 0] = 5.0
    source.log_scales[1, 2] = -25.0
    notes = write_compressed_ply(tmp_path / "a.compressed.ply", source)
    assert len(notes) == 3 and all("\n" not in note for note in notes), notes
    assert "nx, label" in notes[0] and "1 log scales" in notes[1] and "1 SH coefficients" in notes[2]
    decoded = read_compressed_ply(tmp_path / "a.compressed.ply")
    assert decoded.sh_rest[0, 0, 0] == pytest.approx(4.0) and decoded.log_scales[1, 2] == pytest.approx(-20.0)


def test_writer_takes_a_gaussian_scene_and_refuses_nan(tmp_path):
    arrays = synthetic_scene(20, 0)
    scene = GaussianScene(**{k: torch.from_numpy(v) for k, v in arrays.tensors().items()})
    path = tmp_path / "scene.compressed.ply"
    assert write_compressed_ply(path, scene) == []
    assert len(read_compressed_ply(path)) == 20
    arrays.means[3, 1] = np.nan
    with pytest.raises(SplatFormatError, match=r"nan\.compressed\.ply: 1 of 20 Gaussians"):
        write_compressed_ply(tmp_path / "nan.compressed.ply", arrays)
    assert not (tmp_path / "nan.compressed.ply").exists()


def test_numpy_only():
    code = (
        "import sys; sys.modules['torch'] = None\n"
        "import gt2gs_blender.core.scene.compressed_ply as m\n"
        "assert 'torch' not in {k for k, v in sys.modules.items() if v is not None}\n"
    )
    subprocess.run([sys.executable, "-c", code], cwd=ROOT, check=True)
