"""``convert``: a splat file to another format (PLY, compressed PLY, SPZ, .splat; SOG is read only)."""

from __future__ import annotations

import argparse
import warnings
from pathlib import Path
from typing import Any

from ...core.atomic import check_outputs
from ...core.scene.files import FORMATS, WRITE_EXTENSIONS, WRITERS, output_format, read_splats, write_splats
from .args import scene_input, scene_options


def add_convert_command(commands: Any, debug: argparse.ArgumentParser) -> None:
    """The ``convert`` subcommand."""
    writable = ", ".join(WRITE_EXTENSIONS)
    p = commands.add_parser(
        "convert",
        parents=[debug, scene_options()],
        help="convert a splat file to another format",
        description=f"Read any splat file these tools read and write it as OUT ({writable}); the format follows "
        "OUT's name unless --format says otherwise. What the output format cannot keep is printed as a warning.",
    )
    p.add_argument("scene", type=Path, metavar="IN")
    p.add_argument("output", type=Path, metavar="OUT")
    p.add_argument("--format", choices=tuple(WRITERS), help="the output format (default: from OUT's name)")
    p.set_defaults(run=cmd_convert)


def cmd_convert(args: argparse.Namespace) -> None:
    """Read IN, write OUT, and say what the output format dropped."""
    check_outputs([("the output", args.output)], scene_input(args.scene))
    fmt = output_format(args.output, args.format)
    scene = read_splats(args.scene, drop_invalid=args.drop_invalid)
    for note in write_splats(args.output, scene, fmt):
        warnings.warn(f"{args.output}: {note}", stacklevel=1)
    print(f"wrote {len(scene):,} splats to {args.output} ({FORMATS[fmt].label})")
