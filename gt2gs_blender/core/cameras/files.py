"""One entry point for every camera file the tools accept: cameras.json, poses_bounds.npy, a COLMAP
model, or a folder holding one. Each loader raises :class:`CameraFileError` on malformed input."""

from __future__ import annotations

import os
from pathlib import Path

from ..errors import CameraFileError
from .camera import Camera
from .cameras_json import load_cameras_json
from .colmap import _find_colmap_folder, load_colmap
from .llff import load_llff


# ---------------------------------------------------------------------------------------------------
# Dispatch
# ---------------------------------------------------------------------------------------------------
def load_views(path: str | os.PathLike) -> list[Camera]:
    """Cameras from whatever ``path`` is: a cameras.json, a poses_bounds.npy, a COLMAP model
    folder (or its files), or a scene folder holding one of them (looked for in that order).
    LLFF cameras come at the file's full resolution."""
    p = Path(path)
    if not p.exists():
        raise CameraFileError(path, "does not exist")
    if p.is_file():
        if p.suffix.lower() == ".json":
            return load_cameras_json(p)
        if p.suffix.lower() == ".npy":
            return load_llff(p).cameras
        if p.stem in ("cameras", "images", "points3D") and p.suffix in (".bin", ".txt"):
            return load_colmap(p.parent)
        raise CameraFileError(path, "not a camera file (expected cameras.json, poses_bounds.npy or a COLMAP model)")
    if (p / "cameras.json").is_file():
        return load_cameras_json(p / "cameras.json")
    if _find_colmap_folder(p) is not None:
        return load_colmap(p)
    if (p / "poses_bounds.npy").is_file():
        return load_llff(p).cameras
    raise CameraFileError(
        path,
        "no cameras found: expected cameras.json, poses_bounds.npy, or a COLMAP model (here, in sparse/0 or in sparse)",
    )
