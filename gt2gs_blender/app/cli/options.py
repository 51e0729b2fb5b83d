"""The transfer settings as command-line options, generated from their metadata (``core/transfer/config.py``).

One option per user setting, in one argument group per part of the method: booleans as
``--name/--no-name``, numbers typed, choices listed, plus the few short switches a setting keeps for
a common use (``--no-plateau-stop``, ``--full-matching``). Every option defaults to "the preset's",
so ``config_from_args`` applies only what the user typed on top of ``--preset``.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path
from typing import Any

from ...core.transfer.config import TransferConfig, user_settings
from ...core.transfer.presets import DEFAULT_PRESET, GPU_PRESETS, PRESET_HELP, PRESETS, paper_value, preset
from ...core.transfer.setting import PARTS, Setting
from .args import color

METAVARS = {"px": "PX", "°": "DEG", "steps": "N"}


def flag(name: str, meta: Setting) -> str:
    """A setting's command-line flag."""
    return meta.flag or "--" + name.replace("_", "-")


def add_setting_arguments(parser: argparse.ArgumentParser, given: tuple[str, ...] = ()) -> None:
    """``--preset`` and one option per user setting, grouped by part; ``given``: settings whose option the
    command already defines (with ``dest`` = the setting's name), e.g. the shared rendering options."""
    parser.add_argument(
        "--preset",
        choices=tuple(PRESETS),
        default=DEFAULT_PRESET,
        help=f"settings preset (default: {DEFAULT_PRESET}): "
        + "; ".join(
            f"{name}{' (GPU only)' if name in GPU_PRESETS else ''}: {text}" for name, text in PRESET_HELP.items()
        ),
    )
    groups = {part: parser.add_argument_group(f"{title.lower()} settings") for part, title in PARTS.items()}
    for name, meta, kind in user_settings():
        if name in given:
            continue
        group = groups[meta.part]
        group.add_argument(
            flag(name, meta), dest=name, default=None, help=help_text(name, meta), **_argument_kind(meta, kind)
        )
        if meta.switch is not None:
            switch, value, text = meta.switch
            group.add_argument(switch, dest=name, action="store_const", const=value, help=text)


def _argument_kind(meta: Setting, kind: type) -> dict[str, Any]:
    """argparse keywords for a setting of Python type ``kind``."""
    if kind is bool:
        return {"action": argparse.BooleanOptionalAction}
    if kind is tuple:
        return {"type": color, "metavar": "R,G,B"}
    if meta.choices:
        return {"choices": meta.choices}
    if kind is str:
        return {"type": str, "metavar": "PATH"}
    metavar = METAVARS.get(meta.unit, "N" if kind is int else "X")
    return {"type": in_range(meta, kind), "metavar": metavar}


def in_range(meta: Setting, kind: type) -> Callable[[str], Any]:
    """An argparse type: ``kind`` (int or float) within the setting's range, so an error names the user's flag
    ("argument --views: must be at least 1, got 0"), not the setting's field."""

    def parse(text: str) -> Any:
        try:
            value = kind(text)
        except ValueError:
            expected = "an integer" if kind is int else "a number"
            raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}") from None
        problem = meta.problem(value)
        if problem is not None:
            raise argparse.ArgumentTypeError(problem)
        return value

    return parse


def help_text(name: str, meta: Setting) -> str:
    """The option's help: what it does, its unit, the default preset's value and the paper-llff preset's."""
    unit = f" ({meta.unit})" if meta.unit and meta.unit != "steps" else ""
    default, paper = getattr(PRESETS[DEFAULT_PRESET], name), paper_value(name)
    values = f"{DEFAULT_PRESET}: {_shown(default)}" + ("" if paper == default else f", paper-llff: {_shown(paper)}")
    return f"{meta.help}{unit} [{values}]".replace("%", "%%")


def _shown(value: Any) -> str:
    """A setting's value as the help shows it."""
    if isinstance(value, bool):
        return "on" if value else "off"
    if isinstance(value, tuple):
        return ",".join(f"{v:g}" for v in value)
    return "none" if value is None else f"{value:g}" if isinstance(value, float) else str(value)


def config_from_args(args: argparse.Namespace, **extra: Any) -> TransferConfig:
    """The preset with the command line's settings (options not given keep the preset's value)."""
    given = {name: getattr(args, name, None) for name, _, _ in user_settings()}
    given = {name: str(v) if isinstance(v, Path) else v for name, v in given.items()}
    if given.get("background") is not None:
        given["background"] = tuple(given["background"])
    return preset(args.preset, **given, **extra)
