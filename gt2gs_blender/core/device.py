"""Where the engine runs: the torch device asked for, and the CPU thread count for a block."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

import torch

from .errors import GT2GSError


def resolve_device(name: str) -> torch.device:
    """``auto`` = CUDA when present, else CPU; asking for CUDA without it is an error."""
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name == "cuda" and not torch.cuda.is_available():
        raise GT2GSError("device 'cuda' was asked for but torch sees no CUDA device; use --device cpu")
    return torch.device(name)


@contextlib.contextmanager
def cpu_threads(count: int) -> Iterator[None]:
    """torch's (and so the C++ rasterizer's) intra-op thread count set to ``count`` for the block,
    then restored; 0 leaves torch's default (one per physical core)."""
    before = torch.get_num_threads()
    if count > 0:
        torch.set_num_threads(count)
    try:
        yield
    finally:
        if count > 0:
            torch.set_num_threads(before)
