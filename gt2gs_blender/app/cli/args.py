"""Argument types and option groups shared by the commands."""

from __future__ import annotations

import argparse
import math

from ...core.render import BACKENDS


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value <= 0:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}")
    return value


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
    return value


def _floats(text: str, count: int, what: str) -> tuple[float, ...]:
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        values = ()
    if len(values) != count or not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}")
    return values


def _color(text: str) -> tuple[float, float, float]:
    """'R,G,B' in 0..1 (one number means grey)."""
    values = _floats(text, 1, "") if "," not in text else _floats(text, 3, "R,G,B in 0..1")
    rgb = values * 3 if len(values) == 1 else values
    if not all(0.0 <= v <= 1.0 for v in rgb):
        raise argparse.ArgumentTypeError(f"colour components must be in 0..1, got {text!r}")
    return rgb  # type: ignore[return-value]


def _up(text: str) -> str | tuple[float, float, float]:
    """'auto' or an 'x,y,z' vector."""
    return "auto" if text == "auto" else _floats(text, 3, "'auto' or a vector x,y,z")  # type: ignore[return-value]


def _scene_options() -> argparse.ArgumentParser:
    parent = argparse.ArgumentParser(add_help=False)
    parent.add_argument(
        "--drop-invalid", action="store_true", help="load files with NaN/Inf Gaussians by dropping those Gaussians"
    )
    return parent


def _render_options() -> argparse.ArgumentParser:
    parent = argparse.ArgumentParser(add_help=False)
    group = parent.add_argument_group("rendering")
    group.add_argument(
        "--background",
        type=_color,
        default=(1.0, 1.0, 1.0),
        metavar="R,G,B",
        help="background colour, components in 0..1 (default: 1,1,1 = white)",
    )
    group.add_argument(
        "--backend",
        choices=("auto", *BACKENDS),
        default="auto",
        help="rasterizer backend (default: auto = the fastest available)",
    )
    group.add_argument(
        "--device",
        choices=("auto", "cpu", "cuda"),
        default="auto",
        help="torch device (default: auto = cuda when available, else cpu)",
    )
    return parent
