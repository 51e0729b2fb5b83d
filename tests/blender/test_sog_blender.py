"""Blender's WebP decoder (gt2gs_blender.blender.webp) against OpenCV's, in Blender 5.0.1 (bpy module).

SOG files come from PlayCanvas splat-transform (tests/splat_tools.py); the lossless WebP images with
alpha are written here by OpenCV (quality 101 is lossless).
"""

from __future__ import annotations

import tempfile
import zipfile

import numpy as np
import pytest

bpy = pytest.importorskip("bpy", exc_type=ModuleNotFoundError)
cv2 = pytest.importorskip("cv2", exc_type=ModuleNotFoundError)

from gt2gs_blender.blender.webp import decode_webp
from gt2gs_blender.core.errors import SplatFormatError
from gt2gs_blender.core.scene.ply_write import write_ply
from gt2gs_blender.core.scene.sog import decode_webp_cv2, read_sog

from ..splat_tools import donut_path, splat_transform, synthetic_scene

pytestmark = pytest.mark.blender


@pytest.fixture(scope="module")
def sogs(tmp_path_factory):
    """The donut as a .sog zip, and a small SH degree 3 scene as an unpacked folder (its meta.json)."""
    folder = tmp_path_factory.mktemp("sog")
    splat_transform(donut_path(), folder / "donut.sog")
    write_ply(folder / "synthetic.ply", synthetic_scene(500, 3))
    (folder / "unpacked").mkdir()
    splat_transform("-g", "cpu", folder / "synthetic.ply", folder / "unpacked" / "meta.json")
    return {"donut": folder / "donut.sog", "synthetic": folder / "unpacked" / "meta.json"}


def _webp(bgra: np.ndarray) -> bytes:
    ok, data = cv2.imencode(".webp", bgra, [cv2.IMWRITE_WEBP_QUALITY, 101])
    assert ok
    return data.tobytes()


@pytest.mark.parametrize("name", ["donut", "synthetic"])
def test_read_sog_through_blender_equals_the_default_decoder(sogs, name):
    ours = read_sog(sogs[name], decode_webp=decode_webp)
    default = read_sog(sogs[name])
    for key, values in default.tensors().items():
        np.testing.assert_array_equal(ours.tensors()[key], values, err_msg=key)


def test_every_sog_image_decodes_alike(sogs):
    with zipfile.ZipFile(sogs["donut"]) as archive:
        images = {name: archive.read(name) for name in archive.namelist() if name.endswith(".webp")}
    images |= {path.name: path.read_bytes() for path in sogs["synthetic"].parent.glob("*.webp")}
    assert {"sh0.webp", "quats.webp", "shN_centroids.webp", "shN_labels.webp"} <= set(images)
    for name, data in images.items():
        np.testing.assert_array_equal(decode_webp(data, name), decode_webp_cv2(data, name), err_msg=name)


def test_lossless_webp_with_alpha_decodes_exactly(fresh, tmp_path, monkeypatch):
    """Every byte, alpha included, and nothing left behind: no image datablock, no temporary file."""
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    rng = np.random.default_rng(0)
    rgba = rng.integers(1, 256, (37, 53, 4), dtype=np.uint8)  # alpha > 0: see test_sog (libwebp "exact")
    rgba[::4, ::3, 3] = 1
    images = len(bpy.data.images)
    decoded = decode_webp(_webp(cv2.cvtColor(rgba, cv2.COLOR_RGBA2BGRA)), "x.webp")
    assert decoded.dtype == np.uint8
    np.testing.assert_array_equal(decoded, rgba)
    opaque = rgba[..., :3]
    decoded = decode_webp(_webp(cv2.cvtColor(opaque, cv2.COLOR_RGB2BGR)), "y.webp")
    np.testing.assert_array_equal(decoded[..., :3], opaque)
    assert (decoded[..., 3] == 255).all()
    assert len(bpy.data.images) == images
    assert list(tmp_path.iterdir()) == []


def test_an_undecodable_webp_is_an_error_and_leaves_nothing(fresh, tmp_path, monkeypatch):
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    images = len(bpy.data.images)
    with pytest.raises(ValueError, match=r"bad\.webp"):
        decode_webp(b"RIFF\x10\x00\x00\x00WEBPVP8 nonsense", "bad.webp")
    assert len(bpy.data.images) == images
    assert list(tmp_path.iterdir()) == []


def test_a_corrupt_sog_image_is_one_error_through_blender(sogs, tmp_path):
    bad = tmp_path / "bad.sog"
    with zipfile.ZipFile(sogs["donut"]) as source, zipfile.ZipFile(bad, "w") as target:
        for name in source.namelist():
            data = source.read(name)
            target.writestr(name, data[:16] + bytes(len(data) - 16) if name == "quats.webp" else data)
    with pytest.raises(SplatFormatError, match=r"bad\.sog: quats\.webp: does not decode as WebP"):
        read_sog(bad, decode_webp=decode_webp)
