"""Argument types and option groups shared by the commands."""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any, get_args

from ...core.atomic import Named, require_input
from ...core.scene.files import SOG_META
from ...core.transfer.config import SETTINGS
from ...core.transfer.setting import UpAxis


def positive_int(text: str) -> int:
    """An argparse type: an integer above 0."""
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value <= 0:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}")
    return value


def positive_float(text: str) -> float:
    """An argparse type: a finite number above 0."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
    return value


def floats(text: str, count: int, what: str) -> tuple[float, ...]:
    """``count`` comma-separated finite numbers (``what`` says which, in the error)."""
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        values = ()
    if len(values) != count or not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}")
    return values


def color(text: str) -> tuple[float, float, float]:
    """'R,G,B' in 0..1 (one number means grey)."""
    values = floats(text, 1, "") if "," not in text else floats(text, 3, "R,G,B in 0..1")
    rgb = values * 3 if len(values) == 1 else values
    if not all(0.0 <= v <= 1.0 for v in rgb):
        raise argparse.ArgumentTypeError(f"colour components must be in 0..1, got {text!r}")
    return rgb  # type: ignore[return-value]


def up(text: str) -> str | tuple[float, float, float]:
    """'auto', an axis ('+z', '-y', ...: the transfer's Up Axis choices) or an 'x,y,z' vector."""
    if text in get_args(UpAxis):
        return text
    return floats(text, 3, "'auto', an axis such as +z or -y, or a vector x,y,z")  # type: ignore[return-value]


def scene_input(path: Path | None) -> list[Named]:
    """The scene as inputs an output must not overwrite (an unpacked SOG's ``meta.json`` brings its folder),
    after refusing one that is neither a file nor a folder."""
    if path is None:
        return []
    require_input("scene", path, folder=True)
    folder = [("scene's folder", path.parent)] if path.name == SOG_META else []
    return [("scene", path), *folder]


def scene_options() -> argparse.ArgumentParser:
    """The options of every command that reads a scene (a parent parser): --drop-invalid."""
    parent = argparse.ArgumentParser(add_help=False)
    parent.add_argument(
        "--drop-invalid", action="store_true", help="load files with NaN/Inf Gaussians by dropping those Gaussians"
    )
    return parent


def add_scene_command(
    commands: Any, debug: argparse.ArgumentParser, name: str, **texts: str
) -> argparse.ArgumentParser:
    """A subcommand that reads a scene and renders it: the debug, scene and rendering options, then ``texts``
    (``help``, ``description``)."""
    return commands.add_parser(name, parents=[debug, scene_options(), render_options()], **texts)


def render_options(
    background: tuple[float, float, float] = (1.0, 1.0, 1.0), device: bool = True
) -> argparse.ArgumentParser:
    """The rendering options (background, rasterizer, device), worded as the transfer settings they set."""
    parent = argparse.ArgumentParser(add_help=False)
    group = parent.add_argument_group("rendering")
    shown = ",".join(f"{v:g}" for v in background)
    group.add_argument(
        "--background",
        type=color,
        default=background,
        metavar="R,G,B",
        help=f"{SETTINGS['background'].help}, components in 0..1 (default: {shown})",
    )
    group.add_argument(
        "--backend",
        choices=SETTINGS["backend"].choices,
        default="auto",
        help=f"{SETTINGS['backend'].help} (default: auto)",
    )
    if device:
        group.add_argument(
            "--device",
            choices=SETTINGS["device"].choices,
            default="auto",
            help=f"{SETTINGS['device'].help} (default: auto)",
        )
    return parent
