"""Tests of PlayCanvas SOG reading (gt2gs_blender.core.scene.sog).

The oracle is PlayCanvas splat-transform (tests/splat_tools.py): it writes the donut and a synthetic
SH degree 3 scene as a ``.sog`` zip and as an unpacked folder (``meta.json``), and converts each back
to PLY. That PLY is what splat-transform itself reads from the SOG: ours must equal it (float32
rounding aside). Against the source scene, every field must be within what SOG keeps of it, with the
tolerance derived from the file's own meta.json (read here with plain json, not with the module).
splat-transform writes in Morton order, so each read splat is matched to its source by position.

Bad inputs and the decoder's arithmetic use small SOG folders written here, byte by byte, with OpenCV.
"""

from __future__ import annotations

import json
import math
import zipfile
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch

from gt2gs_blender.core.errors import SplatFormatError
from gt2gs_blender.core.scene import codec
from gt2gs_blender.core.scene.arrays import SplatArrays
from gt2gs_blender.core.scene.codec import canonical_quats, sigmoid
from gt2gs_blender.core.scene.ply import read_ply_arrays
from gt2gs_blender.core.scene.ply_write import write_ply
from gt2gs_blender.core.scene.sog import decode_webp_cv2, read_sog

from .splat_tools import donut_path, splat_transform, synthetic_scene

EPS32 = float(np.finfo(np.float32).eps)
QUAT_STEP = math.sqrt(2.0) / 255
"""One step of a stored quaternion component: bytes 0..255 stand for -1/√2..1/√2."""
PALETTE = 32
"""Distinct SH vectors of the synthetic scene (see ``_synthetic``)."""
CASES = [("donut", "zip"), ("donut", "folder"), ("synthetic", "zip"), ("synthetic", "folder")]
MEASURED: dict[str, dict[str, float]] = {}
"""Largest error against the source per case and field (printed with ``pytest -s``; quoted in reports)."""


def _synthetic() -> SplatArrays:
    """``synthetic_scene(2000, 3)`` with its higher SH bands drawn from 32 distinct vectors.

    SOG stores higher bands as a palette of 1024 k-means centroids for 2000 splats: random vectors
    would be averaged in pairs, an error of k-means, not of the format, with no bound to test. With
    fewer distinct vectors than palette entries k-means keeps each one, and what remains is the
    256-entry codebook the palette is quantised to, which is the bound the tests check.
    """
    scene = synthetic_scene(2000, 3)
    rng = np.random.default_rng(1)
    vectors = rng.uniform(-0.3, 0.3, (PALETTE, 15, 3)).astype(np.float32)
    scene.sh_rest = vectors[rng.integers(0, PALETTE, len(scene))]
    return scene


@pytest.fixture(scope="module")
def converted(tmp_path_factory) -> dict[tuple[str, str], dict]:
    """Per case: the source arrays, the SOG path, its meta.json and splat-transform's PLY of the SOG."""
    folder = tmp_path_factory.mktemp("sog")
    sources = {"donut": donut_path(), "synthetic": folder / "synthetic.ply"}
    write_ply(sources["synthetic"], _synthetic())
    cases = {}
    for name, form in CASES:
        sog = folder / f"{name}.sog" if form == "zip" else folder / f"{name}-unpacked" / "meta.json"
        sog.parent.mkdir(exist_ok=True)
        # -g cpu: the SH k-means runs on the GPU by default, and a machine without one fails
        splat_transform("-g", "cpu", sources[name], sog)
        oracle = folder / f"{name}-{form}-oracle.ply"
        splat_transform(sog, oracle)
        meta = json.loads(zipfile.ZipFile(sog).read("meta.json") if form == "zip" else sog.read_text())
        source = read_ply_arrays(sources[name])
        cases[name, form] = {"source": source, "sog": sog, "meta": meta, "oracle": read_ply_arrays(oracle)}
    return cases


def _match(read: np.ndarray, source: np.ndarray, window: int = 128) -> np.ndarray:
    """For each read splat, the index of the nearest source splat among the ``window`` on either side of
    it in x order (read positions are within ~1e-5 of their source, far closer than ``window`` splats
    apart in x; a miss shows as a position error or a match that is not a permutation)."""
    order = np.argsort(source[:, 0], kind="stable")
    xs = source[order, 0]
    best = np.empty(len(read), np.int64)
    offsets = np.arange(-window, window + 1)
    for start in range(0, len(read), 4096):
        block = read[start : start + 4096].astype(np.float64)
        at = np.searchsorted(xs, block[:, 0])[:, None] + offsets
        candidates = order[np.clip(at, 0, len(xs) - 1)]
        distances = ((source[candidates].astype(np.float64) - block[:, None, :]) ** 2).sum(-1)
        best[start : start + 4096] = candidates[np.arange(len(block)), distances.argmin(1)]
    return best


def _nearest_entry(values: np.ndarray, codebook: list[float]) -> np.ndarray:
    """Distance from each value to the nearest codebook entry (the error of a nearest-entry quantiser)."""
    book = np.sort(np.asarray(codebook, np.float32).astype(np.float64))
    v = values.astype(np.float64)
    right = np.clip(np.searchsorted(book, v), 0, len(book) - 1)
    left = np.clip(right - 1, 0, len(book) - 1)
    return np.minimum(np.abs(v - book[left]), np.abs(v - book[right]))


@pytest.mark.parametrize("case", CASES, ids=["-".join(c) for c in CASES])
def test_reads_what_splat_transform_reads(converted, case):
    """The decoder itself: our read equals splat-transform's own read of the SOG, value for value."""
    c = converted[case]
    ours, oracle = read_sog(c["sog"]), c["oracle"]
    assert len(ours) == len(oracle) == c["meta"]["count"] == len(c["source"])
    for key in ("means", "log_scales", "sh_dc", "sh_rest", "opacity_logits"):
        expected = oracle.tensors()[key]
        assert ours.tensors()[key].shape == expected.shape, key
        # both compute in float64 and store float32: at most one float32 rounding apart
        np.testing.assert_allclose(ours.tensors()[key], expected, rtol=2 * EPS32, atol=1e-7, err_msg=key)
    # splat-transform leaves the rebuilt quaternion as decoded; ours is canonical (unit, w >= 0)
    np.testing.assert_allclose(ours.quats, canonical_quats(oracle.quats), atol=1e-6)


@pytest.mark.parametrize("case", CASES, ids=["-".join(c) for c in CASES])
def test_matches_the_source_within_what_sog_keeps(converted, case):
    """Every field of every splat is within the format's quantisation of its source value."""
    c = converted[case]
    ours, meta = read_sog(c["sog"]), c["meta"]
    match = _match(ours.means, c["source"].means)
    assert len(np.unique(match)) == len(ours), "the read splats are not a permutation of the source's"
    src = SplatArrays(**{k: v[match] for k, v in c["source"].tensors().items()}, extras={})
    measured = MEASURED.setdefault("-".join(case), {})

    # positions: 16 bits over [min, max] of t = sign(x) ln(1 + |x|), truncated, so t is at most one step
    # (span / 65535) low; |dx/dt| = 1 + |x|, hence |dx| <= (1 + |x|) expm1(step), plus float32 rounding
    step = (np.asarray(meta["means"]["maxs"]) - np.asarray(meta["means"]["mins"])) / 65535
    bound = (1 + np.abs(src.means)) * (np.expm1(step) + 4 * EPS32)
    error = np.abs(ours.means - src.means)
    measured["means"] = float(error.max())
    assert np.all(error <= bound), f"position error {error.max():.3g} over bound {bound.max():.3g}"

    # log scales and DC colours are labels into 256-entry k-means codebooks (1D, shared by the three axes
    # or channels): the writer picks the nearest entry, so the error is the source value's distance to
    # the codebook, which is small where values are dense and large for a rare outlier
    # (measured: at most half the largest gap between entries inside the codebook's range)
    for key, field, keep in (("scales", "log_scales", None), ("sh0", "sh_dc", src.opacity_logits)):
        error = np.abs(ours.tensors()[field] - src.tensors()[field])
        bound = _nearest_entry(src.tensors()[field], meta[key]["codebook"]) + 1e-6
        if keep is not None:
            # splat-transform's lossless WebP drops the colour of pixels whose alpha (the opacity byte)
            # is 0, as libwebp does without its "exact" option: those splats (opacity < 1/255, invisible)
            # read back colour entry 0 in splat-transform too, so their colour is not compared
            visible = sigmoid(keep) * 255 >= 1
            error, bound = error[visible], bound[visible]
        measured[field] = float(error.max())
        assert np.all(error <= bound), f"{field} error {error.max():.3g} beyond the nearest codebook entry"

    # opacity: sigmoid stored in 8 bits, truncated (read back up to 1/255 low); byte 0 reads as
    # sigmoid(logit(1e-6)), up to 1e-6 high
    low = sigmoid(src.opacity_logits) - sigmoid(ours.opacity_logits)
    measured["opacity"] = float(np.abs(low).max())
    assert low.max() < 1 / 255 + 1e-6 and low.min() > -1e-6 - 1e-7

    # rotations (sign-free): the three smaller components are truncated to steps of √2/255; the largest is
    # rebuilt from the unit norm, |d largest| <= sum |d small| <= 3 steps (the largest is the largest)
    q, s = ours.quats.astype(np.float64), canonical_quats(src.quats)
    error = np.minimum(np.abs(q - s).max(1), np.abs(q + s).max(1))
    measured["quats"] = float(error.max())
    assert error.max() <= 3 * QUAT_STEP + 1e-6

    if ours.sh_rest.shape[1]:
        # every distinct source vector is a palette entry (see _synthetic): codebook error only
        error = np.abs(ours.sh_rest - src.sh_rest)
        bound = _nearest_entry(src.sh_rest, meta["shN"]["codebook"]) + 1e-6
        measured["sh_rest"] = float(error.max())
        assert np.all(error <= bound), f"SH error {error.max():.3g} beyond the nearest codebook entry"
    else:
        assert ours.sh_rest.shape == src.sh_rest.shape == (len(ours), 0, 3)
    print(case, {k: f"{v:.3g}" for k, v in measured.items()})


def test_the_zip_and_the_folder_read_alike(converted):
    """The donut (no k-means, so both conversions are identical) reads the same from either form."""
    zipped, folder = read_sog(converted["donut", "zip"]["sog"]), read_sog(converted["donut", "folder"]["sog"])
    for key, values in zipped.tensors().items():
        np.testing.assert_array_equal(values, folder.tensors()[key], err_msg=key)
    np.testing.assert_array_equal(read_sog(converted["donut", "folder"]["sog"].parent).means, zipped.means)


def test_the_donut_renders_as_its_source(converted):
    """The SOG donut renders like the PLY it came from (PSNR >= 30 dB over four views)."""
    from gt2gs_blender.core.cameras.generate import auto_views
    from gt2gs_blender.core.render import render
    from gt2gs_blender.core.scene.gaussians import GaussianScene

    def scene(arrays: SplatArrays) -> GaussianScene:
        return GaussianScene(**{k: torch.from_numpy(v) for k, v in arrays.tensors().items()})

    source, sog = scene(converted["donut", "zip"]["source"]), scene(read_sog(converted["donut", "zip"]["sog"]))
    cameras = auto_views(source, 4, width=128, height=128)
    a = render(source, cameras).colors.clamp(0, 1)
    b = render(sog, cameras).colors.clamp(0, 1)
    psnr = (-10 * torch.log10(((a - b) ** 2).mean(dim=(1, 2, 3)).clamp_min(1e-12))).tolist()
    print("donut SOG PSNR per view", [f"{p:.1f}" for p in psnr])
    assert min(psnr) >= 30.0


# ---- the default decoder -------------------------------------------------------------------------


def _webp(rgba: np.ndarray) -> bytes:
    """Lossless WebP (OpenCV's quality 101) of RGBA pixels; an all-opaque image is written without alpha."""
    if (rgba[..., 3] == 255).all():
        image = cv2.cvtColor(rgba, cv2.COLOR_RGBA2BGR)
    else:
        image = cv2.cvtColor(rgba, cv2.COLOR_RGBA2BGRA)
    ok, data = cv2.imencode(".webp", image, [cv2.IMWRITE_WEBP_QUALITY, 101])
    assert ok
    return data.tobytes()


def test_the_default_decoder_is_exact_and_keeps_alpha():
    rng = np.random.default_rng(0)
    rgba = rng.integers(0, 256, (37, 53, 4), dtype=np.uint8)
    rgba[::3, ::2, 3] = 0
    decoded = decode_webp_cv2(_webp(rgba), "x.webp")
    assert decoded.shape == rgba.shape and decoded.dtype == np.uint8
    np.testing.assert_array_equal(decoded[..., 3], rgba[..., 3])
    # OpenCV's encoder (libwebp without "exact") may drop the colour under alpha 0: compare the rest
    visible = rgba[..., 3] > 0
    np.testing.assert_array_equal(decoded[visible], rgba[visible])
    opaque = rgba.copy()
    opaque[..., 3] = 255
    np.testing.assert_array_equal(decode_webp_cv2(_webp(opaque), "y.webp"), opaque)
    assert decode_webp_cv2(b"RIFF\x10\x00\x00\x00WEBPVP8 nonsense", "z.webp") is None


# ---- small hand-made SOGs ------------------------------------------------------------------------

TINY_QUATS = np.array(
    # R, G, B, tag (252 + dropped component); the last row's tag is not a tag
    [[255, 0, 128, 252], [10, 200, 30, 253], [0, 0, 0, 254], [128, 64, 255, 255], [90, 90, 90, 7]],
    np.uint8,
)


def _tiny_sog(folder: Path, *, count: int = 5, sh_bands: int = 1) -> Path:
    """A 5-splat SOG (4x2 images, SH degree ``sh_bands``) from chosen bytes; returns its meta.json."""
    folder.mkdir(parents=True, exist_ok=True)
    width, height = 4, 2

    def image(rows: np.ndarray, name: str) -> str:
        pixels = np.zeros((width * height, 4), np.uint8)
        pixels[: len(rows)] = rows
        (folder / name).write_bytes(_webp(pixels.reshape(height, width, 4)))
        return name

    n = 5
    q16 = np.array([[0, 65535, 1], [65535, 0, 256], [32768, 1000, 513], [1, 2, 3], [40000, 50000, 60000]])
    ones = np.full((n, 1), 255, np.uint8)
    means_l = image(np.hstack([(q16 & 255).astype(np.uint8), ones]), "means_l.webp")
    means_u = image(np.hstack([(q16 >> 8).astype(np.uint8), ones]), "means_u.webp")
    labels = np.arange(n * 3, dtype=np.uint8).reshape(n, 3) * 17
    meta = {
        "version": 2,
        "count": count,
        "means": {"mins": [-1.0, 0.0, 0.5], "maxs": [1.0, 0.0, 2.0], "files": [means_l, means_u]},
        "scales": {
            "codebook": np.linspace(-6, -1, 256).tolist(),
            "files": [image(np.hstack([labels, ones]), "s.webp")],
        },
        "quats": {"files": [image(TINY_QUATS, "quats.webp")]},
        "sh0": {
            "codebook": np.linspace(-2, 3, 256).tolist(),
            "files": [image(np.hstack([labels[::-1], [[0], [1], [128], [254], [255]]]), "sh0.webp")],
        },
    }
    if sh_bands:
        k = {1: 3, 2: 8, 3: 15}[sh_bands]
        entries = 70  # two rows of 64 entries, the second partly used
        rng = np.random.default_rng(2)
        centroids = np.full((2 * 64 * k, 4), 255, np.uint8)
        centroids[: entries * k, :3] = rng.integers(0, 256, (entries * k, 3))
        centroids_name = "centroids.webp"
        (folder / centroids_name).write_bytes(_webp(centroids.reshape(2, 64 * k, 4)))
        label16 = np.array([0, 69, 64, 3, 63])
        label_rows = np.stack([label16 & 255, label16 >> 8, np.zeros(n), np.full(n, 255)], 1).astype(np.uint8)
        meta["shN"] = {
            "count": entries,
            "bands": sh_bands,
            "codebook": np.linspace(-0.5, 0.5, 256).tolist(),
            "files": [centroids_name, image(label_rows, "labels.webp")],
        }
    (folder / "meta.json").write_text(json.dumps(meta))
    return folder / "meta.json"


def _expected_tiny(folder: Path) -> dict[str, np.ndarray]:
    """What the tiny SOG holds, computed splat by splat from its meta.json and raw bytes."""
    meta = json.loads((folder / "meta.json").read_text())
    pixels = {name: decode_webp_cv2((folder / name).read_bytes(), name).reshape(-1, 4) for name in _names(meta)}
    low, high = (pixels[name] for name in meta["means"]["files"])
    means, quats = [], []
    for i in range(meta["count"]):
        position = []
        for axis in range(3):
            lo, hi = meta["means"]["mins"][axis], meta["means"]["maxs"][axis]
            t = lo + ((hi - lo) or 1.0) * (int(low[i, axis]) + 256 * int(high[i, axis])) / 65535
            position.append(math.copysign(math.exp(abs(t)) - 1, t))
        means.append(position)
        r, g, b, tag = (int(v) for v in pixels["quats.webp"][i])
        if tag not in (252, 253, 254, 255):
            quats.append([1.0, 0.0, 0.0, 0.0])
            continue
        small = [(v / 255 * 2 - 1) / math.sqrt(2) for v in (r, g, b)]
        q = small[:]
        q.insert(tag - 252, math.sqrt(max(0.0, 1 - sum(v * v for v in small))))
        norm = math.sqrt(sum(v * v for v in q)) * (1 if q[0] >= 0 else -1)
        quats.append([v / norm for v in q])
    scales = np.asarray(meta["scales"]["codebook"], np.float32)[pixels["s.webp"][: meta["count"], :3]]
    sh0 = pixels["sh0.webp"][: meta["count"]]
    return {
        "means": np.array(means),
        "quats": np.array(quats),
        "log_scales": scales,
        "sh_dc": np.asarray(meta["sh0"]["codebook"], np.float32)[sh0[:, :3]],
        "opacity": sh0[:, 3] / 255,
    }


def _names(meta: dict) -> list[str]:
    return [name for key in ("means", "scales", "quats", "sh0", "shN") if key in meta for name in meta[key]["files"]]


def test_a_hand_made_sog_decodes_as_the_format_says(tmp_path):
    meta_path = _tiny_sog(tmp_path / "tiny", sh_bands=2)
    arrays = read_sog(meta_path)
    expected = _expected_tiny(tmp_path / "tiny")
    # y is a flat axis (min == max): read as splat-transform does, a span of 1 from the minimum
    np.testing.assert_allclose(arrays.means, expected["means"], rtol=2 * EPS32, atol=1e-7)
    np.testing.assert_allclose(arrays.quats, expected["quats"], atol=1e-6)
    np.testing.assert_array_equal(arrays.quats[4], [1, 0, 0, 0])
    np.testing.assert_array_equal(arrays.log_scales, expected["log_scales"])
    np.testing.assert_array_equal(arrays.sh_dc, expected["sh_dc"])
    np.testing.assert_allclose(sigmoid(arrays.opacity_logits), np.clip(expected["opacity"], 1e-6, 1 - 1e-6), atol=1e-6)
    # higher bands: label -> entry (64 per row, 8 pixels each) -> codebook, channel by channel
    meta = json.loads(meta_path.read_text())
    centroids = decode_webp_cv2((tmp_path / "tiny" / "centroids.webp").read_bytes(), "c")
    book = np.asarray(meta["shN"]["codebook"], np.float32)
    assert arrays.sh_rest.shape == (5, 8, 3)
    for i, label in enumerate([0, 69, 64, 3, 63]):
        row, column = divmod(label, 64)
        for j in range(8):
            np.testing.assert_array_equal(arrays.sh_rest[i, j], book[centroids[row, column * 8 + j, :3]])


def test_a_sog_without_gaussians_reads_as_empty(tmp_path):
    meta_path = _tiny_sog(tmp_path / "empty", sh_bands=3)
    meta = json.loads(meta_path.read_text())
    meta["count"] = 0
    meta_path.write_text(json.dumps(meta))
    arrays = read_sog(meta_path)
    assert len(arrays) == 0 and arrays.sh_rest.shape == (0, 15, 3)


def test_a_custom_decoder_is_used(tmp_path):
    meta_path = _tiny_sog(tmp_path / "tiny")
    seen = []

    def decoder(data: bytes, name: str) -> np.ndarray:
        seen.append(name)
        return decode_webp_cv2(data, name)

    read_sog(meta_path, decode_webp=decoder)
    assert sorted(seen) == sorted(_names(json.loads(meta_path.read_text())))


# ---- bad input -----------------------------------------------------------------------------------


def _zip(path: Path, folder: Path, *, skip: str = "") -> Path:
    """Zip a SOG folder's files (all but ``skip``) at the zip's root."""
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as archive:
        for file in sorted(folder.iterdir()):
            if file.name != skip:
                archive.write(file, file.name)
    return path


def _edit_meta(meta_path: Path, edit) -> Path:
    meta = json.loads(meta_path.read_text())
    edit(meta)
    meta_path.write_text(json.dumps(meta))
    return meta_path


def _fails(path: Path, *fragments: str, named: Path | None = None, **options) -> str:
    """read_sog fails with one line naming ``named`` (default: ``path``) and saying every fragment."""
    with pytest.raises(SplatFormatError) as info:
        read_sog(path, **options)
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith(f"{named or path}: "), message
    for fragment in fragments:
        assert fragment in message, message
    return message


def test_a_zip_is_read_and_one_without_meta_json_is_refused(tmp_path):
    folder = tmp_path / "tiny"
    _tiny_sog(folder)
    expected = read_sog(folder)
    np.testing.assert_array_equal(read_sog(_zip(tmp_path / "ok.sog", folder)).sh_rest, expected.sh_rest)
    _fails(_zip(tmp_path / "no-meta.sog", folder, skip="meta.json"), "no meta.json")
    _fails(_zip(tmp_path / "no-image.sog", folder, skip="quats.webp"), "quats.webp", "missing from the zip")
    (tmp_path / "not-a-zip.sog").write_bytes(b"PK\x03\x04 but nothing else")
    _fails(tmp_path / "not-a-zip.sog", "zip")
    (tmp_path / "text.sog").write_text("{}")
    _fails(tmp_path / "text.sog", "not a zip archive")


@pytest.mark.parametrize(
    ("edit", "fragments"),
    [
        (lambda m: m.update(version=3), ["unsupported SOG version 3"]),
        (lambda m: m.pop("version"), ["version 1"]),
        (lambda m: m.update(count=-1), ["count"]),
        (lambda m: m.pop("sh0"), ["'sh0'"]),
        (lambda m: m["quats"].update(files=[]), ["quats.files"]),
        (lambda m: m["means"].update(mins=[0, 0]), ["means.mins", "expected 3"]),
        (lambda m: m["scales"]["codebook"].pop(), ["scales.codebook has 255 entries, expected 256"]),
        (lambda m: m["sh0"].update(codebook="no"), ["sh0.codebook"]),
        (lambda m: m["shN"]["codebook"].append(0.0), ["shN.codebook has 257 entries"]),
        (lambda m: m["shN"].update(bands=4), ["shN.bands"]),
        (lambda m: m["quats"].update(files=["../quats.webp"]), ["not a plain name"]),
    ],
    ids=[
        "version-3",
        "version-1",
        "count",
        "no-sh0",
        "no-files",
        "mins",
        "short-codebook",
        "codebook-type",
        "long-sh-codebook",
        "bands",
        "path-escape",
    ],
)
def test_a_bad_meta_json_is_one_error_naming_it(tmp_path, edit, fragments):
    meta_path = _edit_meta(_tiny_sog(tmp_path / "tiny"), edit)
    _fails(meta_path, *fragments)
    _fails(_zip(tmp_path / "bad.sog", tmp_path / "tiny"), "meta.json", *fragments)


def test_meta_json_that_is_not_json_is_one_error(tmp_path):
    meta_path = _tiny_sog(tmp_path / "tiny")
    meta_path.write_text('{"version": 2, "count": ')
    _fails(meta_path, "not JSON")
    _fails(meta_path.parent, "not JSON", named=meta_path)
    meta_path.write_text("[2]")
    _fails(meta_path, "not a JSON object")
    renamed = meta_path.with_name("scene.json")  # a meta file of another name is read and named as given
    renamed.write_text("{")
    _fails(renamed, "not JSON")


def test_a_corrupt_webp_is_one_error_naming_it(tmp_path):
    folder = tmp_path / "tiny"
    meta_path = _tiny_sog(folder)
    data = (folder / "sh0.webp").read_bytes()
    (folder / "sh0.webp").write_bytes(data[:20] + bytes(len(data) - 20))
    _fails(meta_path, "does not decode as WebP", named=folder / "sh0.webp")
    _fails(_zip(tmp_path / "bad.sog", folder), "sh0.webp: does not decode as WebP")


def test_a_failing_or_wrong_decoder_is_one_error(tmp_path):
    meta_path = _tiny_sog(tmp_path / "tiny")

    def raises(data: bytes, name: str) -> np.ndarray:
        raise RuntimeError("no codec")

    _fails(
        meta_path, "does not decode as WebP", "no codec", named=tmp_path / "tiny" / "means_l.webp", decode_webp=raises
    )
    _fails(meta_path, "does not decode", named=tmp_path / "tiny" / "means_l.webp", decode_webp=lambda d, n: None)
    _fails(
        meta_path,
        "not (H, W, 4) uint8",
        named=tmp_path / "tiny" / "means_l.webp",
        decode_webp=lambda d, n: np.zeros((2, 4, 4)),
    )


def test_images_too_small_for_the_count_are_refused(tmp_path):
    folder = tmp_path / "tiny"
    _fails(
        _edit_meta(_tiny_sog(folder), lambda m: m.update(count=9)),
        "4x2 pixels, too small for 9",
        named=folder / "means_l.webp",
    )
    meta_path = _tiny_sog(tmp_path / "sh", sh_bands=1)
    _edit_meta(meta_path, lambda m: m["shN"].update(bands=2))  # centroids 192 wide: degree 1, not 2
    _fails(meta_path, "192 pixels wide, expected 512", named=tmp_path / "sh" / "centroids.webp")
    _edit_meta(meta_path, lambda m: m["shN"].update(bands=1, count=60))  # labels 63, 64 and 69 are past it
    _fails(meta_path, "3 Gaussians use palette entries past the 60", named=tmp_path / "sh" / "labels.webp")


def test_a_zip_bomb_is_refused_before_it_is_inflated(tmp_path, monkeypatch):
    folder = tmp_path / "tiny"
    _edit_meta(_tiny_sog(folder), lambda m: m["means"]["files"].__setitem__(1, "big.webp"))
    (folder / "big.webp").write_bytes(bytes(2**20))  # 1 MiB of zeros deflates to about 1 KiB
    bomb = _zip(tmp_path / "bomb.sog", folder)
    assert bomb.stat().st_size < 2**16
    monkeypatch.setattr(codec, "MAX_DECOMPRESSED", 2**19)
    _fails(bomb, "big.webp", "declares 1048576 bytes uncompressed, over the 524288-byte limit")
    monkeypatch.setattr(codec, "MAX_DECOMPRESSED", 100)  # meta.json is checked too
    _fails(bomb, "meta.json", "over the 100-byte limit")


def test_non_finite_values_are_refused_or_dropped(tmp_path):
    # the sh0 colour labels are 0, 17, ..., 238 in reverse order: entry 17 is splat 4's green
    meta_path = _edit_meta(_tiny_sog(tmp_path / "tiny"), lambda m: m["sh0"]["codebook"].__setitem__(17, float("nan")))
    _fails(meta_path, "non-finite", named=meta_path)
    with pytest.warns(UserWarning, match="dropped 1 of 5"):
        assert len(read_sog(meta_path, drop_invalid=True)) == 4


def test_a_missing_path_is_one_error(tmp_path):
    _fails(tmp_path / "nothing.sog", "cannot read")
