"""``batch``: run a manifest of transfers (scenes x textures x settings) on a local Dask cluster or a running one.

dask is imported when the command runs, not when the CLI loads: the other commands (and Blender's worker)
never need it.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from ...core.errors import GT2GSError
from .args import positive_int


def cmd_batch(args: argparse.Namespace) -> None:
    """Run the batch; print where the summary is; fail (exit 2) when any job failed."""
    from ..batch.cluster import run_batch

    result = run_batch(
        args.manifest,
        args.out,
        scheduler=args.scheduler,
        workers=args.workers,
        threads=args.threads,
        retries=args.retries,
        resume=args.resume,
    )
    print("\n".join(f"wrote {path}" for path in result.files))
    if result.failed:
        raise GT2GSError(f"{len(result.failed)} of {len(result.rows)} jobs failed; see {result.files[1]}")


def add_batch_command(commands: Any, debug: argparse.ArgumentParser) -> None:
    """The ``batch`` subcommand."""
    p = commands.add_parser(
        "batch",
        parents=[debug],
        help="run many transfers from a manifest (CSV or TOML), on this machine or a Dask cluster",
        description="Run every job of MANIFEST (a .csv with a header row: scene, texture, then optional preset, "
        "output, cameras and any setting's name; or a .toml with [[job]] and [[product]] tables) into one "
        "folder per job in --out, with a summary table (CSV + Markdown) and a contact sheet.",
    )
    p.add_argument("manifest", type=Path, metavar="MANIFEST")
    p.add_argument("--out", type=Path, required=True, metavar="DIR", help="the batch's output folder")
    p.add_argument(
        "--scheduler",
        metavar="tcp://HOST:PORT",
        help="a running Dask scheduler (default: a local cluster on this machine)",
    )
    p.add_argument(
        "--workers",
        type=positive_int,
        metavar="N",
        help="local workers, one job each at a time (default: the cores over the threads per job, or one per GPU)",
    )
    p.add_argument(
        "--threads",
        type=positive_int,
        metavar="N",
        help="CPU threads per job (default: a quarter of the cores, at most 4; on a cluster, each host's cores "
        "shared by its worker threads)",
    )
    p.add_argument(
        "--retries",
        type=_count,
        default=2,
        metavar="N",
        help="more tries for a job that crashed or whose worker died (default: 2); a job's bad input fails at once",
    )
    p.add_argument(
        "--resume",
        action="store_true",
        help="keep the jobs whose folder already holds their result made with the same inputs and settings",
    )
    p.set_defaults(run=cmd_batch)


def _count(text: str) -> int:
    """A count of 0 or more."""
    if not text.isdigit():
        raise argparse.ArgumentTypeError(f"expected 0 or a positive integer, got {text!r}")
    return int(text)
