"""Error types shown to users as one readable line (CLI, Blender reports)."""
from __future__ import annotations

import os


class GT2GSError(Exception):
    """Base of every error the engine raises on purpose; its message is meant for the user."""


class InputFileError(GT2GSError):
    """A file given by the user cannot be used; the message names the file and the problem."""

    def __init__(self, path: str | os.PathLike, problem: str) -> None:
        self.path = os.fspath(path)
        self.problem = problem
        super().__init__(f"{self.path}: {problem}")


class PlyFormatError(InputFileError):
    """A PLY file is malformed or is not a 3D Gaussian Splatting file."""


class CameraFileError(InputFileError):
    """A camera/pose file (cameras.json, poses_bounds.npy, COLMAP model) is malformed."""
