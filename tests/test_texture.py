"""Texture loading: every image kind a user may hand in becomes RGB float32 in [0, 1], or a clear error."""

from __future__ import annotations

import struct
import warnings
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest

from gt2gs_blender.core.errors import InputFileError
from gt2gs_blender.core.transfer.texture import load_texture


def _rgb_pattern(height: int = 80, width: int = 96) -> np.ndarray:
    """A uint8 RGB image with distinct, spatially varying channels."""
    y, x = np.mgrid[0:height, 0:width]
    return np.stack([x * 255 // (width - 1), y * 255 // (height - 1), (x + y) % 256], axis=-1).astype(np.uint8)


def _write(path: Path, image: np.ndarray) -> Path:
    assert cv2.imwrite(str(path), image)
    return path


def _load_quietly(path: Path) -> np.ndarray:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        return load_texture(path)


def _png_chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def _palette_png(indices: np.ndarray, palette: np.ndarray) -> bytes:
    """An 8-bit palette PNG (colour type 3), which cv2.imwrite cannot produce."""
    height, width = indices.shape
    header = struct.pack(">IIBBBBB", width, height, 8, 3, 0, 0, 0)
    raw = b"".join(b"\x00" + row.astype(np.uint8).tobytes() for row in indices)
    return b"".join(
        [
            b"\x89PNG\r\n\x1a\n",
            _png_chunk(b"IHDR", header),
            _png_chunk(b"PLTE", palette.astype(np.uint8).tobytes()),
            _png_chunk(b"IDAT", zlib.compress(raw)),
            _png_chunk(b"IEND", b""),
        ]
    )


def _with_exif_orientation(jpeg: bytes, orientation: int) -> bytes:
    """Insert an APP1 Exif segment holding only the Orientation tag right after the JPEG SOI marker."""
    tiff = b"MM\x00\x2a" + struct.pack(">I", 8) + struct.pack(">H", 1)
    tiff += struct.pack(">HHIHH", 0x0112, 3, 1, orientation, 0) + struct.pack(">I", 0)
    payload = b"Exif\x00\x00" + tiff
    return jpeg[:2] + b"\xff\xe1" + struct.pack(">H", len(payload) + 2) + payload + jpeg[2:]


def test_rgb_png_is_rgb_order_in_unit_range(tmp_path):
    rgb = _rgb_pattern()
    texture = _load_quietly(_write(tmp_path / "t.png", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)))
    assert texture.dtype == np.float32 and texture.shape == (80, 96, 3)
    np.testing.assert_array_equal(texture, rgb.astype(np.float32) / 255.0)


def test_grayscale_png_becomes_three_equal_channels(tmp_path):
    gray = _rgb_pattern()[:, :, 0]
    texture = _load_quietly(_write(tmp_path / "g.png", gray))
    assert texture.shape == (80, 96, 3)
    for c in range(3):
        np.testing.assert_array_equal(texture[:, :, c], gray / np.float32(255.0))


def test_sixteen_bit_png_keeps_its_precision(tmp_path):
    rgb16 = _rgb_pattern().astype(np.uint16) * 257 + np.arange(96, dtype=np.uint16)[None, :, None]
    texture = _load_quietly(_write(tmp_path / "d.png", cv2.cvtColor(rgb16, cv2.COLOR_RGB2BGR)))
    np.testing.assert_allclose(texture, rgb16 / 65535.0, atol=1e-7)


def test_palette_png_is_expanded(tmp_path):
    palette = np.array([[255, 0, 0], [0, 128, 255], [10, 20, 30]])
    indices = (np.arange(64 * 72).reshape(64, 72) // 7) % 3
    path = tmp_path / "p.png"
    path.write_bytes(_palette_png(indices, palette))
    np.testing.assert_array_equal(_load_quietly(path), palette[indices].astype(np.float32) / 255.0)


def test_rgba_fills_transparent_pixels_with_the_mean_visible_colour(tmp_path):
    bgra = np.zeros((70, 70, 4), np.uint8)
    bgra[:, :35] = (0, 0, 255, 255)  # opaque red on the left
    bgra[:, 35:] = (255, 255, 255, 0)  # transparent junk (white) on the right
    with pytest.warns(UserWarning, match="50% of the texture is transparent"):
        texture = load_texture(_write(tmp_path / "a.png", bgra))
    np.testing.assert_allclose(texture, np.broadcast_to([1.0, 0.0, 0.0], texture.shape))


def test_exif_orientation_of_a_photograph_is_applied(tmp_path):
    image = np.zeros((64, 128, 3), np.uint8)
    image[:, 64:] = 255  # left black, right white
    _, jpeg = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, 95])
    path = tmp_path / "photo.jpg"
    path.write_bytes(_with_exif_orientation(jpeg.tobytes(), 6))  # 6: rotate 90 degrees clockwise to display
    texture = load_texture(path)
    assert texture.shape == (128, 64, 3)
    assert texture[:60].mean() < 0.05 and texture[68:].mean() > 0.95


def test_unicode_path_is_readable(tmp_path):
    rgb = _rgb_pattern()
    texture = _load_quietly(_write(tmp_path / "t.png", rgb).rename(tmp_path / "tëxture_木.png"))
    assert texture.shape == (80, 96, 3)


@pytest.mark.parametrize("content", [b"", b"not an image at all", b"\x89PNG\r\n\x1a\n" + b"\x00" * 40])
def test_corrupt_files_raise_input_file_error(tmp_path, content):
    path = tmp_path / "bad.png"
    path.write_bytes(content)
    with pytest.raises(InputFileError, match=r"bad.png: not an image file OpenCV can decode"):
        load_texture(path)


def test_missing_file_and_fully_transparent_image_raise_input_file_error(tmp_path):
    with pytest.raises(InputFileError, match="cannot read the texture"):
        load_texture(tmp_path / "missing.png")
    with pytest.raises(InputFileError, match="fully transparent"):
        load_texture(_write(tmp_path / "clear.png", np.zeros((64, 64, 4), np.uint8)))


def test_constant_and_tiny_textures_warn(tmp_path):
    with pytest.warns(UserWarning, match="constant colour"):
        load_texture(_write(tmp_path / "c.png", np.full((80, 80, 3), 77, np.uint8)))
    with pytest.warns(UserWarning, match="tiny"):
        load_texture(_write(tmp_path / "s.png", _rgb_pattern(20, 30)))
