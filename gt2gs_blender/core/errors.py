"""Error types shown to users as one readable line (CLI, Blender reports)."""

from __future__ import annotations

import os
import re


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


class NotGaussianPlyError(PlyFormatError):
    """A valid PLY that holds no Gaussians: a mesh or a plain point cloud."""


class SplatFormatError(InputFileError):
    """A splat file (compressed PLY, SOG, SPZ, .splat) is malformed, truncated or of an unknown version, or
    cannot hold the scene a writer was given."""


class CameraFileError(InputFileError):
    """A camera/pose file (cameras.json, poses_bounds.npy, COLMAP model) is malformed."""


MEMORY_ADVICE = "try the preview preset, fewer views or a lower resolution"
"""What to change when a job does not fit in memory (the worker, the CLI and Blender say it)."""
_ALLOCATION_FAILURES = ("can't allocate memory", "not enough memory", "out of memory")
"""How torch's allocators word a failure: CPU (Linux, Windows) and CUDA/MPS (torch.OutOfMemoryError)."""
_REQUEST = re.compile(r"allocate ([\d.]+) ?(bytes|[KMGTPE]iB)", re.IGNORECASE)
"""The size in torch's ("tried to allocate 541155328 bytes", "Tried to allocate 20.00 MiB") and numpy's messages."""


def out_of_memory_message(exc: BaseException) -> str | None:
    """The user's line when ``exc`` is a failed allocation (MemoryError, or torch's RuntimeError from
    its CPU or GPU allocator, which is not a MemoryError), with the size asked for; None otherwise."""
    text = str(exc)
    if not (
        isinstance(exc, MemoryError)
        or (isinstance(exc, RuntimeError) and any(words in text for words in _ALLOCATION_FAILURES))
    ):
        return None
    request = _REQUEST.search(text)
    if request is None:
        return f"ran out of memory: {MEMORY_ADVICE}"
    amount, unit = request.groups()
    if unit.lower() == "bytes":
        n = float(amount)
        amount, unit = (
            (f"{n / 2**30:.1f}", "GiB")
            if n >= 2**30
            else (f"{n / 2**20:.0f}", "MiB")
            if n >= 2**20
            else (f"{n:,.0f}", "bytes")
        )
    return f"ran out of memory (an allocation of {amount} {unit} failed): {MEMORY_ADVICE}"
