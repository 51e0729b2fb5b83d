"""PNG files the front ends write (renders, depth maps, previews, before/after strips): one writer."""

from __future__ import annotations

import os

import cv2
import numpy as np

from ..core.atomic import atomic_write


def write_png(path: str | os.PathLike, pixels: np.ndarray) -> None:
    """An (H,W,3) uint8 RGB or (H,W) uint8/uint16 grey image as a PNG, written atomically."""
    image = np.ascontiguousarray(pixels[..., ::-1] if pixels.ndim == 3 else pixels)
    ok, data = cv2.imencode(".png", image)
    if not ok:
        raise OSError(f"{path}: could not encode the PNG")
    atomic_write(path, data.tobytes())
