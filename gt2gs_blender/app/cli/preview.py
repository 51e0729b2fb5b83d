"""``preview``: the picture a transfer will start from, drawn before any optimisation (seconds), so an angle,
texture size or part can be chosen headless as the add-on's orientation preview lets an artist choose it."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from ...core.atomic import all_or_nothing, check_outputs
from ...core.transfer.orientation_preview import preview
from ..images import write_png
from .args import add_scene_command, positive_int
from .transfer import add_run_arguments, check_named_as, read_run, run_inputs

SIZE = 512
"""The picture's longest side unless ``--size`` says otherwise."""


def add_preview_command(commands: Any, debug: argparse.ArgumentParser) -> None:
    """The ``preview`` subcommand."""
    p = add_scene_command(
        commands,
        debug,
        "preview",
        help="picture how the texture will lie before a transfer (PNG)",
        description="Draw the first view of the run `transfer` would start with the same options (the texture "
        "laid out on the scene, before any optimisation) as a PNG, and say how many splats the run starts from.",
    )
    p.add_argument("-o", "--output", type=Path, required=True, metavar="PNG", help="the picture (.png)")
    add_run_arguments(p)
    p.add_argument(
        "--size", type=positive_int, default=SIZE, metavar="PX", help=f"the picture's longest side (default {SIZE})"
    )
    p.set_defaults(run=cmd_preview)


def cmd_preview(args: argparse.Namespace) -> None:
    """Check the paths, draw the run's first view as it will start, write it."""
    outputs = [("-o", args.output)]
    check_outputs(outputs, run_inputs(args))
    check_named_as(outputs, {"-o": ".png"})
    run = read_run(args)
    shown = preview(run.scene, run.texture, run.views, run.config, size=args.size, region=run.region)
    with all_or_nothing([args.output]):
        write_png(args.output, shown.image)
    width, height = shown.size
    print(
        f"preview: {args.output} (the run's first view; it will start from {shown.splats:,} splats "
        f"and work {shown.views} views at {width}x{height})"
    )
