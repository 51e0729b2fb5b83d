"""Atomic file output: write beside the target, then rename over it, so readers never see half a file."""

from __future__ import annotations

import os
import secrets
from collections.abc import Iterable
from pathlib import Path


def atomic_write(path: str | os.PathLike, chunks: Iterable[bytes | memoryview] | bytes | str) -> None:
    """Write ``chunks`` (buffers: bytes, memoryviews, numpy arrays; or one str as UTF-8) atomically.

    The temp file is created with ordinary umask permissions and is removed on any failure, so a
    failed or interrupted write leaves the old file (if any) untouched and nothing behind.
    """
    path = Path(path)
    if isinstance(chunks, str):
        chunks = [chunks.encode("utf-8")]
    elif isinstance(chunks, (bytes, bytearray, memoryview)):
        chunks = [chunks]
    tmp = path.with_name(f".{path.name}.{secrets.token_hex(4)}.tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0), 0o666)
    try:
        with os.fdopen(fd, "wb") as f:
            for chunk in chunks:
                f.write(chunk)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
