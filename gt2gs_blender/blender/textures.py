"""The chosen texture as Blender sees it: a cheap check that it decodes, and its thumbnail for the panel.

The check runs before a worker starts, so an unreadable texture is a one-line error naming the file, not
a failure minutes later inside the worker. The engine decodes textures with OpenCV, which Blender's own
Python lacks: the file's signature must be one of the image formats OpenCV reads, and a format Blender
reads too must decode in Blender (a damaged file). Thumbnails are ``bpy.utils.previews`` images, not
image datablocks, so showing one leaves nothing in the .blend.
"""

from __future__ import annotations

import os

import bpy
import bpy.utils.previews

SIGNATURES = (
    (b"\x89PNG\r\n\x1a\n", "PNG"),
    (b"\xff\xd8\xff", "JPEG"),
    (b"II*\x00", "TIFF"),
    (b"MM\x00*", "TIFF"),
    (b"BM", "BMP"),
    (b"v/1\x01", "EXR"),
    (b"#?RADIANCE", "HDR"),
    (b"#?RGBE", "HDR"),
    (b"\x00\x00\x00\x0cjP  \r\n\x87\n", "JPEG 2000"),
    (b"\xff\x4f\xff\x51", "JPEG 2000"),
    (b"GIF8", "GIF"),
    (b"\x59\xa6\x6a\x95", "Sun raster"),
    (b"PF\n", "PFM"),
    (b"Pf\n", "PFM"),
    *((f"P{n}".encode(), "PNM") for n in range(1, 8)),
)
"""Leading bytes of the image formats OpenCV decodes (WebP, a RIFF container, is checked apart)."""
BLENDER_DECODES = {"PNG", "JPEG", "TIFF", "BMP", "EXR", "HDR", "JPEG 2000", "WebP"}
"""Formats Blender decodes too, so a file of one that Blender cannot read is damaged."""
EXPECTED = "PNG, JPEG, TIFF, BMP, WebP or EXR"
_thumbnails: dict[str, object] = {}


def image_format(head: bytes) -> str | None:
    """The image format a file's first bytes announce, None when they announce none OpenCV reads."""
    if head[:4] == b"RIFF" and head[8:12] == b"WEBP":
        return "WebP"
    return next((name for signature, name in SIGNATURES if head.startswith(signature)), None)


def texture_problem(path: str) -> str | None:
    """Why the texture file ``path`` cannot be used (one line naming it), None when it looks decodable."""
    try:
        with open(path, "rb") as f:
            head = f.read(16)
    except OSError as exc:
        return f"cannot read the texture {path} ({exc.strerror or exc})"
    kind = image_format(head)
    if kind is None:
        return f"the texture {path} is not an image file: choose a {EXPECTED} picture"
    if kind in BLENDER_DECODES and not _blender_decodes(path):
        return f"the texture {path} is a damaged {kind} file that cannot be decoded: save it again or choose another"
    return None


def _blender_decodes(path: str) -> bool:
    """Whether Blender decodes the image at ``path`` (loaded into a temporary datablock, removed again)."""
    try:
        image = bpy.data.images.load(path, check_existing=False)
    except RuntimeError:
        return False
    try:
        return image.size[0] > 0 and image.size[1] > 0
    finally:
        bpy.data.images.remove(image)


def thumbnail(settings):
    """The panel's thumbnail of the chosen texture (an ImagePreview), None when there is none to show."""
    if settings.texture_source == "IMAGE":
        image = settings.texture_image
        return None if image is None else image.preview_ensure()
    path = os.path.abspath(bpy.path.abspath(settings.texture_path)) if settings.texture_path else ""
    if not path or not os.path.isfile(path):
        return None
    if "collection" not in _thumbnails:
        _thumbnails["collection"] = bpy.utils.previews.new()
    collection = _thumbnails["collection"]
    key = f"{path}:{os.path.getmtime(path)}"  # a file saved again gets a new thumbnail
    return collection.get(key) or collection.load(key, path, "IMAGE")


def release_thumbnails() -> None:
    """Free the thumbnails (at unregister)."""
    collection = _thumbnails.pop("collection", None)
    if collection is not None:
        bpy.utils.previews.remove(collection)
