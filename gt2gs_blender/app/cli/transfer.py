"""``transfer``: re-texture a scene file with a texture photo and write the stylised scene."""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ...core.atomic import Named, all_or_nothing, check_outputs, require_input
from ...core.cameras.camera import Camera
from ...core.cameras.files import load_views
from ...core.cameras.llff import load_llff
from ...core.errors import InputFileError
from ...core.scene.files import output_format, read_scene
from ...core.scene.gaussians import GaussianScene
from ...core.transfer.config import SETTINGS, TransferConfig
from ..jobs import load_region, read_texture, run_transfer, summary, write_before_after
from ..progress import TerminalProgress
from .args import add_scene_command, scene_input
from .options import add_setting_arguments, config_from_args, in_range
from .parts import part_region


def add_view_arguments(p: argparse.ArgumentParser) -> None:
    """Where the views come from: a cameras file, an LLFF folder, or a number of automatic views."""
    views = p.add_mutually_exclusive_group()
    views.add_argument(
        "--cameras",
        type=Path,
        metavar="FILE_OR_DIR",
        help="cameras.json, poses_bounds.npy, a COLMAP model, or a folder holding one",
    )
    views.add_argument("--llff", type=Path, metavar="DIR", help="an LLFF capture folder (poses_bounds.npy)")
    add_views_option(views, "N automatic views around the scene")


def add_views_option(parser: Any, help: str) -> None:
    """``--views N``: the count of automatic views, within the ``n_views`` setting's range."""
    parser.add_argument("--views", dest="n_views", type=in_range(SETTINGS["n_views"], int), metavar="N", help=help)


def _views(args: argparse.Namespace) -> list[Camera] | None:
    if args.cameras is not None:
        return load_views(args.cameras)
    if args.llff is not None:
        return load_llff(args.llff).cameras
    return None


def _views_source(args: argparse.Namespace) -> str | None:
    """The cameras file or LLFF folder the views come from (None: automatic views), for messages."""
    source = args.cameras if args.cameras is not None else args.llff
    return None if source is None else str(source)


def run_inputs(args: argparse.Namespace) -> list[Named]:
    """Refuse inputs that are no file (or folder), before any work; the inputs a run reads (scene, texture, region,
    views, weights), which no output may overwrite."""
    inputs = scene_input(args.scene)
    others = (
        ("texture", args.texture, False),
        ("region", args.region, False),
        ("cameras", args.cameras, True),
        ("LLFF folder", args.llff, True),
        ("weights", args.weights_path, True),
    )
    for what, path, folder in others:
        if path is not None:
            require_input(what, path, folder=folder)
            inputs.append((what, path))
    return inputs


def check_paths(args: argparse.Namespace) -> list[Named]:
    """Refuse inputs that are no file (or folder) and outputs that would overwrite an input or cannot be
    written, before any work; the outputs given."""
    given = (("-o", args.output), ("--report", args.report), ("--strip", args.strip))
    outputs = [(what, path) for what, path in given if path is not None]
    check_outputs(outputs, run_inputs(args))
    output_format(args.output)  # a format the tools write (SOG is read only)
    check_named_as(outputs, NAMED_AS)
    return outputs


def check_named_as(outputs: list[Named], kinds: dict[str, str]) -> None:
    """Refuse an output whose name does not end as the kind of file it is written as (``kinds``: flag -> suffix)."""
    for what, path in outputs:
        suffix = kinds.get(what)
        if suffix is not None and Path(path).suffix.lower() != suffix:
            raise InputFileError(path, f"{what} is written as {suffix.upper()[1:]}; end its name with {suffix}")


NAMED_AS = {"--report": ".json", "--strip": ".png"}
"""The file kind each side output is written as, which its name must say (a picture named .jpg would be a PNG)."""


@dataclass(frozen=True)
class Run:
    """What a run reads, from the command line: the scene, the texture, the splats it restyles (None: all), its
    views (None: automatic) and settings."""

    scene: GaussianScene
    texture: np.ndarray
    region: np.ndarray | None
    views: list[Camera] | None
    config: TransferConfig


def read_run(args: argparse.Namespace) -> Run:
    """Read a run's inputs (checked before by :func:`run_inputs`) and settings."""
    scene = read_scene(args.scene, drop_invalid=args.drop_invalid)
    texture = read_texture(args.texture)
    region = load_region(args.region, len(scene)) if args.region is not None else None
    if args.part is not None:
        region = part_region(scene, args.part, args.scene)
    return Run(scene, texture, region, _views(args), config_from_args(args))


def cmd_transfer(args: argparse.Namespace) -> None:
    """Re-texture a scene, write the stylised scene (and report, strip), all or nothing; print a summary."""
    outputs = check_paths(args)
    with all_or_nothing(path for _, path in outputs):
        report = _transfer(args)
    print("\n".join(f"{_WROTE[what]}: {path}" for what, path in outputs))
    print(summary(report))


_WROTE = {"-o": "stylised scene", "--report": "report", "--strip": "before/after"}


def _transfer(args: argparse.Namespace) -> dict:
    """Read the inputs, run the transfer, write the outputs; the run's report."""
    run = read_run(args)
    with TerminalProgress("transfer") as bar:
        result = run_transfer(
            run.scene,
            run.texture,
            run.views,
            run.config,
            args.output,
            report=args.report,
            region=run.region,
            progress=bar,
            scene_name=args.scene,
            views_name=_views_source(args),
        )
    if args.strip is not None:
        config = run.config
        write_before_after(args.strip, run.scene, result.scene, run.texture, run.views, config.up, config.view_kind)
    return result.report


def add_transfer_command(commands: Any, debug: argparse.ArgumentParser) -> None:
    """The ``transfer`` subcommand."""
    p = add_scene_command(
        commands,
        debug,
        "transfer",
        help="re-texture a 3DGS .ply with a texture photo (GT²-GS)",
        description="Re-texture SCENE.ply with TEXTURE so the texture follows the geometry from every view; "
        "writes the stylised scene to OUT.ply.",
    )
    p.add_argument(
        "-o",
        "--output",
        type=Path,
        required=True,
        metavar="OUT",
        help="the stylised scene: .ply, .compressed.ply, .spz or .splat",
    )
    add_run_arguments(p)
    p.add_argument("--report", type=Path, metavar="R.json", help="write the run's report as JSON")
    p.add_argument("--strip", type=Path, metavar="PNG", help="also write a before/after picture")
    p.set_defaults(run=cmd_transfer)


def add_run_arguments(p: argparse.ArgumentParser) -> None:
    """What a run reads and how it runs (``transfer`` and ``preview``): the scene, the texture, the views, every
    setting, and the splats it restyles."""
    p.add_argument("scene", type=Path, metavar="SCENE")
    p.add_argument("texture", type=Path, metavar="TEXTURE")
    add_view_arguments(p)
    add_setting_arguments(p, given=GIVEN)
    only = p.add_mutually_exclusive_group()
    only.add_argument(
        "--region",
        type=Path,
        metavar="MASK.npy",
        help="restyle only these Gaussians (.npy of indices or booleans); the rest stay bit-identical",
    )
    only.add_argument(
        "--part",
        type=int,
        metavar="N",
        help="restyle only part N of the scene (see the parts command: found from the splats' colour and "
        "position, 0 the largest); the rest stay bit-identical",
    )


GIVEN = ("background", "backend", "device", "n_views")
"""Settings whose options ``transfer`` and ``demo`` define themselves (rendering options, views)."""
