"""The command line, ``python -m gt2gs_blender``: inspect, render, convert and re-texture splat files (one, or a
batch of many), run the demo, fit one.

Errors the user can fix (bad files, bad arguments, a job too large for the memory) print one line on stderr
and exit with 2; any other exception is a bug, also reported in one line, with exit code 1; ``--debug`` adds
the traceback. Rasterizer warnings (e.g. a backend falling back) are shown as ``gt2gs: warning: ...``. SIGTERM and
SIGHUP (a closed terminal, ``kill``, a job scheduler's time limit) stop a command as Ctrl-C does: what it was
writing is removed, and it exits with 128 + the signal's number.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import os
import signal
import sys
import threading
import traceback
import warnings
from collections.abc import Iterator, Sequence
from typing import NoReturn

from ...core.errors import GT2GSError, out_of_memory_message
from . import transfer as transfer_cmd
from .batch import add_batch_command
from .convert import add_convert_command
from .demo import add_demo_command
from .fit import add_fit_command
from .info import add_info_command
from .parts import add_parts_command
from .preview import add_preview_command
from .render import add_render_command

PROG = "gt2gs"
PARSER_PROG = "python -m gt2gs_blender"


EXIT_INTERNAL, EXIT_USER, EXIT_PIPE = 1, 2, 141


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; return the exit status (0 success, 2 user error, 1 internal error)."""
    parser = build_parser()
    argv = sys.argv[1:] if argv is None else list(argv)
    if "" in argv:  # argparse's Path('') is the current folder: an empty name would silently become '.'
        return _fail(False, f"'' (argument {argv.index('') + 1}): an empty file name or value; give one", EXIT_USER)
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help (0) or a usage error argparse already printed (2)
        return exc.code if isinstance(exc.code, int) else EXIT_USER
    with _reporting_to_stderr(), _stopping_on_signals():
        try:
            args.run(args)
        except Stopped as exc:
            return _fail(args.debug, f"stopped by {signal.Signals(exc.signum).name}", 128 + exc.signum)
        except KeyboardInterrupt:
            return _fail(args.debug, "interrupted", 130)
        except BrokenPipeError:  # the reader stopped reading (``| head``): nothing went wrong here
            return _reader_gone()
        except (GT2GSError, OSError, ValueError) as exc:
            return _fail(args.debug, _user_message(exc), EXIT_USER)
        except Exception as exc:  # out of memory (the user can ask for less), else a bug: one line unless --debug
            memory = out_of_memory_message(exc)
            if memory is not None:
                return _fail(args.debug, memory, EXIT_USER)
            hint = "" if args.debug else " (run with --debug for the traceback)"
            return _fail(args.debug, f"internal error{hint}: {type(exc).__name__}: {exc}", EXIT_INTERNAL)
    return 0


class Stopped(KeyboardInterrupt):
    """A termination signal, raised where the command is, so it unwinds as Ctrl-C does (temp files removed)."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum


STOP_SIGNALS = tuple(getattr(signal, name) for name in ("SIGTERM", "SIGHUP") if hasattr(signal, name))
"""The signals that stop a command cleanly (SIGHUP does not exist on Windows)."""


@contextlib.contextmanager
def _stopping_on_signals() -> Iterator[None]:
    """Turn ``STOP_SIGNALS`` into :class:`Stopped` for the command's run (the main thread only: Python delivers
    signals there); the previous handlers come back after it."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def stop(signum: int, frame: object) -> NoReturn:
        raise Stopped(signum)

    previous = {signum: signal.signal(signum, stop) for signum in STOP_SIGNALS}
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


class OneLineParser(argparse.ArgumentParser):
    """argparse with a usage error in one line, as every other error (its subcommands' parsers are of this class)."""

    def error(self, message: str) -> NoReturn:
        """Print ``gt2gs: error: <command>: <message>`` (with a hint for a value that starts with '-') and exit 2."""
        if message.startswith("argument ") and message.endswith("expected one argument"):
            message += " (write a value that starts with '-' with '=', e.g. --up=-y)"
        command = self.prog.removeprefix(PARSER_PROG).strip()
        print(f"{PROG}: error: {command + ': ' if command else ''}{message} (see --help)", file=sys.stderr)
        sys.exit(EXIT_USER)


def build_parser() -> argparse.ArgumentParser:
    """The argparse tree: global --debug, then the info / render / demo subcommands."""
    debug = argparse.ArgumentParser(add_help=False)
    debug.add_argument("--debug", action="store_true", default=argparse.SUPPRESS, help="print the traceback of errors")
    parser = OneLineParser(
        prog=PARSER_PROG,
        allow_abbrev=False,
        description="GT²-GS texture transfer for 3D Gaussian Splatting: command-line tools.",
    )
    parser.add_argument("--debug", action="store_true", help="print the traceback of errors")
    commands = parser.add_subparsers(title="commands", metavar="COMMAND", required=True)
    add_info_command(commands, debug)
    add_parts_command(commands, debug)
    add_render_command(commands, debug)
    add_demo_command(commands, debug)
    add_fit_command(commands, debug)
    transfer_cmd.add_transfer_command(commands, debug)
    add_preview_command(commands, debug)
    add_convert_command(commands, debug)
    add_batch_command(commands, debug)
    return parser


def _user_message(exc: BaseException) -> str:
    """One line for the user; OSErrors name their file."""
    if isinstance(exc, OSError) and exc.filename is not None and exc.strerror:
        message = f"{exc.filename}: {exc.strerror}"
    else:
        message = str(exc) or type(exc).__name__
    return " ".join(message.split())


def _reader_gone() -> int:
    """Exit as a Unix tool does when its output pipe closes (128 + SIGPIPE), silencing the flush at exit."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())
    os.close(devnull)
    return EXIT_PIPE


def _fail(debug: bool, message: str, code: int) -> int:
    if debug:
        traceback.print_exc()
    print(f"{PROG}: error: {' '.join(message.split())}", file=sys.stderr)
    return code


@contextlib.contextmanager
def _reporting_to_stderr() -> Iterator[None]:
    """Show the engine's log warnings and Python warnings as one 'gt2gs: warning:' line each."""
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter(f"{PROG}: warning: %(message)s"))
    handler.setLevel(logging.WARNING)
    logger = logging.getLogger("gt2gs_blender")
    logger.addHandler(handler)

    def show(message: Warning | str, *_: object, **__: object) -> None:
        print(f"{PROG}: warning: {message}", file=sys.stderr)

    try:
        with warnings.catch_warnings():
            warnings.showwarning = show
            yield
    finally:
        logger.removeHandler(handler)
