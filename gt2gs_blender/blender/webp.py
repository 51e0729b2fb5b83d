"""Decode WebP images with Blender's own image loader, for ``core.scene.sog.read_sog(decode_webp=...)``.

Blender ships no Python WebP decoder and the engine's default (OpenCV) may not be installed yet, so the
bytes go through a temporary file and ``bpy.data.images.load``. The image is marked as data
(Non-Color, channel-packed alpha) before its pixels are read, so neither colour management nor alpha
association touches the values: the float pixels are exactly byte / 255 and round back to the bytes.
"""

from __future__ import annotations

import contextlib
import os
import tempfile

import bpy
import numpy as np


def decode_webp(data: bytes, name: str) -> np.ndarray:
    """The (H, W, 4) uint8 RGBA pixels of a WebP file, top row first; ``ValueError`` if Blender cannot read it."""
    fd, temp = tempfile.mkstemp(prefix="gt2gs-", suffix=".webp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        try:
            image = bpy.data.images.load(temp, check_existing=False)
        except RuntimeError as exc:
            raise ValueError(f"Blender cannot load {name}: {exc}") from None
        try:
            return _pixels(image, name)
        finally:
            bpy.data.images.remove(image)
    finally:
        with contextlib.suppress(OSError):
            os.unlink(temp)


def _pixels(image: bpy.types.Image, name: str) -> np.ndarray:
    """An image's pixels as uint8 RGBA rows, top first, unaltered by colour management."""
    image.colorspace_settings.is_data = True
    image.alpha_mode = "CHANNEL_PACKED"
    width, height = image.size
    channels = image.channels
    if width * height == 0 or not image.has_data or channels not in (3, 4):
        raise ValueError(f"Blender cannot decode {name} as an image")
    values = np.empty(width * height * channels, np.float32)
    image.pixels.foreach_get(values)
    rgba = np.rint(values.reshape(height, width, channels)[::-1] * 255.0).clip(0, 255).astype(np.uint8)
    if channels == 3:
        rgba = np.concatenate([rgba, np.full((height, width, 1), 255, np.uint8)], axis=2)
    return np.ascontiguousarray(rgba)
