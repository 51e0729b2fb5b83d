"""Load a texture photograph as RGB float32 in [0, 1], whatever image file OpenCV can decode.

Choices:
- Files are read as bytes and decoded with ``cv2.imdecode`` (``cv2.imread`` fails on non-ASCII paths
  on Windows, where Blender users keep their textures).
- Grayscale is repeated to RGB; palette images are expanded by OpenCV; 8-bit, 16-bit and other
  integer samples are divided by their type's maximum; float images (EXR, HDR, float TIFF) are
  clipped to [0, 1] with a warning when they leave it.
- Transparent pixels carry no texture, and their RGB is often junk: images with alpha are
  composited over the alpha-weighted mean colour of the image, so they add neither a false colour
  to the colour statistics nor a false edge to the features. A fully transparent image is an error.
- The EXIF orientation of photographs is applied (a texture's orientation matters to the angle
  control). OpenCV ignores it when it keeps the alpha channel, so images with alpha are used as stored.
- A constant texture (nothing to transfer but its colour) and a tiny one (heavily upscaled by the
  texture bank) load with a warning; so do float images with NaN/Inf samples (replaced by 0 or 1).
- Textures larger than ``MAX_SIDE`` on a side are downscaled to it (area filter, before the float
  conversion) with a warning: the bank uses a few hundred pixels of height per scale, and a 16k
  texture as float32 RGB alone would take 3 GiB. OpenCV refuses images above 2^30 pixels.
"""

from __future__ import annotations

import contextlib
import os
import sys
import warnings
from collections.abc import Iterator

import cv2
import numpy as np

from ..errors import InputFileError

TINY_SIDE = 64
"""Textures with a side shorter than this are upscaled several times by the bank: warn."""

CONSTANT_STD = 1e-3
"""Textures whose pixel standard deviation is below this (in [0, 1] units) count as constant."""

MAX_SIDE = 8192
"""Textures with a longer side are downscaled to this many pixels."""

MAX_ASPECT = 16
"""A texture at most this many times as long as it is wide: the bank scales it to the run's texture size and turns
it, and a longer strip holds too little across to turn (its scaled length also passes OpenCV's 32,767 px warps)."""

ARRAY_NAME = "the texture array"
"""What errors and warnings call a texture a caller passed as an array (it has no file name)."""


def load_texture(path: str | os.PathLike) -> np.ndarray:
    """The image at ``path`` as an (H, W, 3) float32 RGB array in [0, 1].

    Raises ``InputFileError`` when the file cannot be read or decoded, or holds no visible pixel.
    """
    try:
        with open(path, "rb") as f:
            data = np.frombuffer(f.read(), dtype=np.uint8)
    except OSError as exc:
        raise InputFileError(path, f"cannot read the texture ({exc.strerror or exc})") from exc
    image = _limit_size(_decode(data, path), path)
    rgb = _to_rgb01(image, path)
    _require_tileable(rgb, path)
    _warn_if_unusable(rgb, path)
    return rgb


def read_texture(texture: np.ndarray | str | os.PathLike) -> np.ndarray:
    """A texture given as a file (:func:`load_texture`) or as an array (:func:`texture_from_array`)."""
    return texture_from_array(texture) if isinstance(texture, np.ndarray) else load_texture(texture)


def texture_from_array(texture: np.ndarray) -> np.ndarray:
    """A caller's (H, W, 3+) texture array as a run reads it (RGB float32 in [0, 1], contiguous), held to a texture
    file's rules: integers scaled to [0, 1], NaN/Inf replaced and values clipped with a warning, a long strip
    refused."""
    array = np.asarray(texture)
    if array.ndim != 3 or array.shape[2] < 3 or min(array.shape[:2]) < 1:
        raise InputFileError(ARRAY_NAME, f"has shape {array.shape}; give an (H, W, 3) RGB array")
    rgb = np.ascontiguousarray(_unit_range(array[..., :3], ARRAY_NAME))
    _require_tileable(rgb, ARRAY_NAME)
    _warn_if_unusable(rgb, ARRAY_NAME)
    return rgb


def _decode(data: np.ndarray, path: str | os.PathLike) -> np.ndarray:
    """Decode with OpenCV, keeping alpha when there is some, else applying the EXIF orientation."""
    try:
        with _native_stderr_hidden():
            image = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None
    except cv2.error as exc:  # codecs refuse some files with an exception rather than None
        raise InputFileError(path, _codec_problem(str(exc))) from None
    if (image is None or image.size == 0) and data[:4].tobytes() == b"GIF8":
        raise InputFileError(path, "a GIF, which is not supported as a texture: save it as PNG, JPEG, TIFF or WebP")
    if image is None or image.size == 0:
        raise InputFileError(path, "not an image file OpenCV can decode (texture expected: PNG, JPEG, TIFF, ...)")
    if image.ndim == 3 and image.shape[2] in (2, 4):
        return image
    with _native_stderr_hidden():
        oriented = cv2.imdecode(data, cv2.IMREAD_ANYDEPTH | cv2.IMREAD_ANYCOLOR)
    return image if oriented is None else oriented


@contextlib.contextmanager
def _native_stderr_hidden() -> Iterator[None]:
    """Hide what the codecs' C code prints on file descriptor 2 (libpng's "PNG input buffer is incomplete",
    OpenCV's warnings): the one error line that follows says it in the user's terms."""
    sys.stderr.flush()
    try:
        saved = os.dup(2)
    except OSError:  # no descriptor 2 (a GUI process on Windows): nothing to hide
        yield
        return
    try:
        with open(os.devnull, "wb") as null:
            os.dup2(null.fileno(), 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def _codec_problem(message: str) -> str:
    """A one-line reason for an OpenCV decoder exception."""
    if "OpenEXR codec is disabled" in message:
        return (
            "EXR textures need OpenCV's OpenEXR codec, which is off by default: set the environment "
            "variable OPENCV_IO_ENABLE_OPENEXR=1 before starting, or convert the texture to PNG/TIFF"
        )
    if "CV_IO_MAX_IMAGE_PIXELS" in message:
        return "the image has more than 2^30 pixels, more than OpenCV will decode"
    return f"OpenCV cannot decode the image ({message.strip().splitlines()[-1]})"


def _limit_size(image: np.ndarray, path: str | os.PathLike) -> np.ndarray:
    """Downscale (area filter) so that neither side exceeds ``MAX_SIDE``, with a warning."""
    height, width = image.shape[:2]
    if max(height, width) <= MAX_SIDE:
        return image
    factor = MAX_SIDE / max(height, width)
    size = (max(1, round(width * factor)), max(1, round(height * factor)))
    warnings.warn(
        f"{os.fspath(path)}: the texture is {width}x{height} px; downscaled to {size[0]}x{size[1]} "
        f"(at most {MAX_SIDE} px a side)",
        stacklevel=3,
    )
    return cv2.resize(image, size, interpolation=cv2.INTER_AREA)


def _to_rgb01(image: np.ndarray, path: str | os.PathLike) -> np.ndarray:
    """OpenCV's gray / gray+alpha / BGR / BGRA samples of any depth -> RGB float32 in [0, 1]."""
    values = _unit_range(image, path)
    if values.ndim == 2:
        values = values[:, :, None]
    channels = values.shape[2]
    colour = _composite_alpha(values[:, :, :-1], values[:, :, -1], path) if channels in (2, 4) else values
    if colour.shape[2] == 1:
        return np.ascontiguousarray(np.repeat(colour, 3, axis=2))
    return np.ascontiguousarray(colour[:, :, 2::-1])


def _unit_range(image: np.ndarray, path: str | os.PathLike) -> np.ndarray:
    """Samples as float32 in [0, 1]: integers divided by their type's maximum, floats clipped."""
    if np.issubdtype(image.dtype, np.integer):
        return image.astype(np.float32) / np.float32(np.iinfo(image.dtype).max)
    values = image.astype(np.float32)
    bad = int(np.count_nonzero(~np.isfinite(values)))
    if bad:
        warnings.warn(
            f"{os.fspath(path)}: {bad} NaN/Inf texture samples were replaced (NaN and -Inf by 0, +Inf by 1)",
            stacklevel=2,
        )
        values = np.nan_to_num(values, nan=0.0, posinf=1.0, neginf=0.0)
    if values.min() < 0.0 or values.max() > 1.0:
        warnings.warn(f"{os.fspath(path)}: float texture values outside [0, 1] were clipped", stacklevel=2)
    return np.clip(values, 0.0, 1.0)


def _composite_alpha(colour: np.ndarray, alpha: np.ndarray, path: str | os.PathLike) -> np.ndarray:
    """Composite over the alpha-weighted mean colour (see the module notes)."""
    total = float(alpha.sum(dtype=np.float64))
    if total <= 0.0:
        raise InputFileError(path, "the texture is fully transparent")
    a = alpha[:, :, None]
    if a.min() < 1.0:
        mean = (colour * a).sum(axis=(0, 1), dtype=np.float64) / total
        warnings.warn(f"{os.fspath(path)}: {_transparency(alpha)}; composited over its mean colour", stacklevel=2)
        return (colour * a + mean.astype(np.float32) * (1.0 - a)).astype(np.float32)
    return colour


def _require_tileable(rgb: np.ndarray, path: str | os.PathLike) -> None:
    """Refuse a strip longer than ``MAX_ASPECT``: one line naming the texture, not an error deep in the bank."""
    height, width = rgb.shape[:2]
    if max(height, width) > MAX_ASPECT * min(height, width):
        raise InputFileError(
            path, f"the texture is {width}x{height} px, longer than {MAX_ASPECT}:1; crop it to a more even shape"
        )


def _warn_if_unusable(rgb: np.ndarray, path: str | os.PathLike) -> None:
    """Warn about textures that load but cannot give a good transfer."""
    height, width = rgb.shape[:2]
    if min(height, width) < TINY_SIDE:
        warnings.warn(
            f"{os.fspath(path)}: the texture is tiny ({width}x{height} px); it will be upscaled and look blurry",
            stacklevel=2,
        )
    if float(rgb.reshape(-1, 3).std(axis=0).max()) < CONSTANT_STD:  # per channel: (R, G, B) constant
        warnings.warn(
            f"{os.fspath(path)}: the texture is a constant colour; only its colour can be transferred",
            stacklevel=2,
        )


def _transparency(alpha: np.ndarray) -> str:
    """How much of the texture is fully transparent, and how much only partly (alpha between 0 and 1)."""
    clear, partial = float((alpha <= 0.0).mean()), float(((alpha > 0.0) & (alpha < 1.0)).mean())
    if not clear:
        return f"{partial:.0%} of the texture is semi-transparent"
    return f"{clear:.0%} of the texture is transparent" + (f" and {partial:.0%} semi-transparent" if partial else "")
