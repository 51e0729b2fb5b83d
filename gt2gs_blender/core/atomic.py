"""The user's files: inputs checked before they are opened, outputs checked before any work, and outputs
written atomically (beside the target, then renamed over it) and, for a run with several, all or nothing.

The rules, one place each: an output never names an input or another output (``same_file``: through
``./``, symlinks or hard links; inside an input folder, one of its files); an output's folder exists and
takes a new file, the output is no folder and its name fits; an input is a regular file (or, where one is
meant, a folder), never a pipe or a device that would block the read. Errors name the user's path.
"""

from __future__ import annotations

import contextlib
import os
import secrets
import stat
from collections.abc import Iterable, Iterator, Sequence
from contextvars import ContextVar
from dataclasses import dataclass, field
from pathlib import Path

from .errors import InputFileError

PathLike = str | os.PathLike
Named = tuple[str, PathLike | None]
"""A file the user named, with what the command calls it ("the scene", "--report"); None: not given."""

ZIP_MAGIC = b"PK\x03\x04"
"""How a zip archive starts (a SOG file, a .npz, a torch.save file)."""

NAME_MAX = 255
"""The longest file name (bytes) the common file systems take."""

_KINDS = {stat.S_ISFIFO: "a named pipe", stat.S_ISCHR: "a device", stat.S_ISBLK: "a device", stat.S_ISSOCK: "a socket"}


@dataclass
class _Stage:
    """The outputs of an all-or-nothing block, the temp files written for them, the folders it made."""

    targets: frozenset[str]
    pending: dict[str, tuple[Path, Path]] = field(default_factory=dict)
    made: list[Path] = field(default_factory=list)


_STAGE: ContextVar[_Stage | None] = ContextVar("gt2gs_stage", default=None)


def same_file(a: PathLike, b: PathLike) -> bool:
    """Whether two paths name one file: equal once ``./`` and symlinks are resolved, or one inode (hard links)."""
    if os.path.realpath(a) == os.path.realpath(b):
        return True
    try:
        return os.path.samefile(a, b)
    except (OSError, ValueError):
        return False


def overwrites(output: PathLike, source: PathLike) -> bool:
    """Whether writing ``output`` would change the input ``source``: the same file, or a file in its folder."""
    return same_file(output, source) or (os.path.isdir(source) and os.path.exists(output) and _under(output, source))


def require_input(what: str, path: PathLike, *, folder: bool = False) -> None:
    """Refuse an input that is not a regular file (or, with ``folder``, a folder) before it is opened: a pipe
    or a device would block the read. A missing file is left to the reader, which names what it expected."""
    try:
        mode = os.stat(path).st_mode
    except (OSError, ValueError):
        return
    if stat.S_ISREG(mode) or (folder and stat.S_ISDIR(mode)):
        return
    expected = "a file or a folder" if folder else "a file"
    raise InputFileError(path, f"the {what} is {_kind(mode)}, not {expected}")


def read_head(path: PathLike, size: int) -> bytes:
    """The first ``size`` bytes of a user's file, to know what it is before a reader opens it (OSError as ``open``)."""
    with open(path, "rb") as f:
        return f.read(size)


def check_outputs(outputs: Sequence[Named], inputs: Sequence[Named], new_folders: Sequence[PathLike] = ()) -> None:
    """Refuse, before any work, outputs that would overwrite an input or another output or cannot be written.

    ``new_folders`` are output folders the run makes when absent: the files inside need not exist yet.
    """
    given = [(what, Path(path)) for what, path in inputs if path is not None and os.path.exists(path)]
    for folder in new_folders:
        _require_folder_writable(Path(folder))
    seen: list[tuple[str, Path]] = []
    for what, path in outputs:
        if path is None:
            continue
        path = Path(path)
        for source_what, source in given:
            if overwrites(path, source):
                raise InputFileError(path, f"{what} would overwrite the {source_what} ({source}); choose another path")
        for other_what, other in seen:
            if same_file(path, other):
                raise InputFileError(path, f"{what} and {other_what} name the same file; choose two paths")
        _require_file_writable(path, in_new_folder=any(_under(path.parent, Path(f)) for f in new_folders))
        seen.append((what, path))


@contextlib.contextmanager
def all_or_nothing(outputs: Iterable[PathLike], new_folders: Sequence[PathLike] = ()) -> Iterator[None]:
    """Within the block, atomic writes to ``outputs`` are staged beside them and renamed over them together
    when the block succeeds; on failure none is written, and the folders made for them are removed."""
    stage = _Stage(frozenset(os.path.realpath(p) for p in outputs))
    token = _STAGE.set(stage)
    try:
        for folder in new_folders:
            _make_folder(Path(folder), stage.made)
        yield
        _STAGE.reset(token)
        token = None
        _commit(stage)
    except BaseException:
        for tmp, _ in stage.pending.values():
            tmp.unlink(missing_ok=True)
        for folder in reversed(stage.made):
            with contextlib.suppress(OSError):
                folder.rmdir()
        raise
    finally:
        if token is not None:
            _STAGE.reset(token)


def atomic_write(path: PathLike, chunks: Iterable[bytes | memoryview] | bytes | str) -> None:
    """Write ``chunks`` (buffers: bytes, memoryviews, numpy arrays; or one str as UTF-8) atomically.

    The temp file is created with ordinary umask permissions (a file it replaces keeps its own) and is removed
    on any failure, also a signal the moment after it was created, so a failed or interrupted write leaves the old
    file (if any) untouched and nothing behind; an error names ``path``, never the temp file. Inside
    :func:`all_or_nothing` the rename waits for the block's end.
    """
    path = Path(path)
    if isinstance(chunks, str):
        chunks = [chunks.encode("utf-8")]
    elif isinstance(chunks, (bytes, bytearray, memoryview)):
        chunks = [chunks]
    tmp = path.with_name(f".{path.name[:48]}.{secrets.token_hex(4)}.tmp")
    try:
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0), 0o666)
            with os.fdopen(fd, "wb") as f:
                for chunk in chunks:
                    f.write(chunk)
            _keep_mode(tmp, path)
            _finish(tmp, path)
        except BaseException as exc:
            if not isinstance(exc, FileExistsError):  # only os.open's O_EXCL raises it: that file is not ours
                tmp.unlink(missing_ok=True)
            raise
    except OSError as exc:
        if exc.errno is None or exc.filename not in (None, str(tmp), os.fspath(path)):
            raise
        raise OSError(exc.errno, exc.strerror, os.fspath(path)) from exc


def _keep_mode(tmp: Path, path: Path) -> None:
    """Give the temp file the permissions of the file it will replace (a private file stays private)."""
    with contextlib.suppress(FileNotFoundError):
        os.chmod(tmp, stat.S_IMODE(os.stat(path).st_mode))


def _finish(tmp: Path, path: Path) -> None:
    """Rename the written temp file over ``path``, or hold it for the all-or-nothing block that owns ``path``."""
    stage = _STAGE.get()
    key = os.path.realpath(path)
    if stage is None or key not in stage.targets:
        os.replace(tmp, path)
        return
    earlier = stage.pending.pop(key, None)
    if earlier is not None:
        earlier[0].unlink(missing_ok=True)
    stage.pending[key] = (tmp, path)


def _commit(stage: _Stage) -> None:
    """Rename every staged temp file over its output; an error names the output."""
    while stage.pending:
        tmp, path = stage.pending.pop(next(iter(stage.pending)))
        try:
            os.replace(tmp, path)
        except OSError as exc:
            tmp.unlink(missing_ok=True)
            raise OSError(exc.errno, exc.strerror, os.fspath(path)) from exc


def _make_folder(folder: Path, made: list[Path]) -> None:
    """Make ``folder`` and its missing parents, noting each one made."""
    missing = [p for p in (folder, *folder.parents) if not p.exists()]
    for path in reversed(missing):
        path.mkdir()
        made.append(path)


def _kind(mode: int) -> str:
    """What a non-regular file is, in words."""
    if stat.S_ISDIR(mode):
        return "a folder"
    return next((words for test, words in _KINDS.items() if test(mode)), "not a regular file")


def _under(path: PathLike, folder: PathLike) -> bool:
    """Whether ``path`` is ``folder`` or inside it (resolved)."""
    resolved, top = os.path.realpath(path), os.path.realpath(folder)
    return resolved == top or resolved.startswith(top.rstrip(os.sep) + os.sep)


def _require_file_writable(path: Path, *, in_new_folder: bool) -> None:
    """The output's name fits, it is no folder or pipe, and its folder exists and takes a new file."""
    size = len(os.fsencode(path.name))
    if size > NAME_MAX:
        raise InputFileError(path, f"cannot be written: the file name is too long ({size} bytes, at most {NAME_MAX})")
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        mode = None
    except OSError as exc:
        raise InputFileError(path, f"cannot be written: {_reason(exc, path.parent)}") from None
    if mode is not None and not stat.S_ISREG(mode):
        raise InputFileError(path, f"cannot be written: it is {_kind(mode)}; name a file")
    if mode is not None and not mode & (stat.S_IWUSR | stat.S_IWGRP | stat.S_IWOTH):
        raise InputFileError(path, "cannot be written: the file is read-only; make it writable or choose another path")
    if not in_new_folder:
        _probe(path, path.parent)


def _require_folder_writable(folder: Path) -> None:
    """An output folder is a folder, or can be made: its nearest existing parent is a folder that takes one."""
    size = max((len(os.fsencode(part)) for part in folder.parts), default=0)
    if size > NAME_MAX:
        raise InputFileError(folder, f"cannot be written: a name in it is too long ({size} bytes, at most {NAME_MAX})")
    existing = next((p for p in (folder, *folder.parents) if os.path.lexists(p)), Path("."))
    if existing == folder and folder.is_dir():
        _probe(folder, folder)
    elif not existing.is_dir():
        raise InputFileError(folder, f"cannot be written: {existing} is not a folder")
    else:
        _probe(folder, existing)


def _probe(path: Path, folder: Path) -> None:
    """Create and remove a file in ``folder`` (what the write of ``path`` will do), naming ``path`` on failure."""
    probe = folder / f".gt2gs-check.{secrets.token_hex(4)}.tmp"
    try:
        os.close(os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
    except OSError as exc:
        raise InputFileError(path, f"cannot be written: {_reason(exc, folder)}") from None
    os.unlink(probe)


def _reason(exc: OSError, folder: Path) -> str:
    """Why a path in ``folder`` cannot be written, in the user's terms."""
    if not os.path.lexists(folder):
        return f"the folder {folder} does not exist"
    if not folder.is_dir():
        return f"{folder} is not a folder"
    if isinstance(exc, FileNotFoundError):
        return f"the folder {folder} takes no new files"
    return exc.strerror or str(exc)
