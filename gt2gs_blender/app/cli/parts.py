"""``parts``: the parts of a splat file found from its splats' colour and position (``core.scene.parts``), to
texture one of them with ``transfer --part N`` (the guitar's body and not its stand, the robot and not the ground)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from ...core.atomic import require_input
from ...core.errors import InputFileError
from ...core.scene.files import read_scene
from ...core.scene.gaussians import GaussianScene
from ...core.scene.parts import Parts, find_parts
from .args import scene_options


def add_parts_command(commands: Any, debug: argparse.ArgumentParser) -> None:
    """The ``parts`` subcommand."""
    p = commands.add_parser(
        "parts",
        parents=[debug, scene_options()],
        help="list the parts of a splat file (by colour and position), for transfer --part N",
        description="List the parts of a 3D Gaussian Splatting file found from its splats' colour and position, "
        "largest first: re-texture one of them with `transfer --part N`.",
    )
    p.add_argument("scene", type=Path, metavar="SCENE")
    p.add_argument("--json", action="store_true", help="print the parts as JSON")
    p.set_defaults(run=cmd_parts)


def cmd_parts(args: argparse.Namespace) -> None:
    """Print the parts of a scene file, as text or JSON."""
    require_input("scene", args.scene, folder=True)
    parts = find_parts(read_scene(args.scene, drop_invalid=args.drop_invalid))
    rows = describe(parts)
    if args.json:
        print(json.dumps(rows, indent=2))
        return
    print(f"{args.scene}: {len(parts)} parts (restyle one with: transfer --part N)")
    for row in rows:
        print(f"  part {row['part']:>2}: {row['splats']:>9,} splats ({row['share']:6.1%}), colour {row['colour']}")


def describe(parts: Parts) -> list[dict[str, Any]]:
    """One row per part: its number, splat count, share of the splats and mean colour as #rrggbb."""
    total = max(int(parts.sizes.sum()), 1)
    return [
        {
            "part": p,
            "splats": int(size),
            "share": int(size) / total,
            "colour": "#" + "".join(f"{round(float(c) * 255):02x}" for c in colour),
        }
        for p, (size, colour) in enumerate(zip(parts.sizes, parts.colours, strict=True))
    ]


def part_region(scene: GaussianScene, part: int, path: Path) -> Any:
    """(N,) bool: the splats of ``part`` of the scene read from ``path``; a one-line error naming the file and the
    parts it has when there is no such part."""
    parts = find_parts(scene)
    try:
        return parts.mask(part)
    except IndexError as exc:
        raise InputFileError(path, f"{exc} (list them with: python -m gt2gs_blender parts {path})") from None
