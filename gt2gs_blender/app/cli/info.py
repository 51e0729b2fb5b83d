"""``info``: what a 3DGS file holds (count, SH degree, bounds, properties), as text or JSON; without a file,
what a run would use on this machine (the rasterizer and why, compiler, numba, weights)."""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path
from typing import Any

from ...core.atomic import require_input
from ...core.scene.files import COMPRESSED_PLY, FORMATS, PLY, detect_format, read_scene
from ...core.scene.gaussians import GaussianScene
from ...core.scene.inria import NORMAL_NAMES
from ...core.scene.ply_header import read_ply_header
from ..machine import machine_info
from .args import scene_options

ROBUST_QUANTILE = 0.98
"""Robust bounds ignore the 2 % most extreme means on each side of each axis (as auto_views does)."""


def add_info_command(commands: Any, debug: argparse.ArgumentParser) -> None:
    """The ``info`` subcommand."""
    p = commands.add_parser(
        "info",
        parents=[debug, scene_options()],
        help="format, count, SH degree, bounds and properties of a splat file; without one, this machine's rasterizer",
        description="Describe a 3D Gaussian Splatting file (PLY, compressed PLY, SOG, SPZ or .splat) and what its "
        "format keeps. Without SCENE: what a run would use on this machine (which rasterizer runs and why, the C++ "
        "compiler, numba, the feature weights).",
    )
    p.add_argument("scene", type=Path, nargs="?", metavar="SCENE")
    p.add_argument("--json", action="store_true", help="print the description as JSON")
    p.set_defaults(run=cmd_info)


def cmd_info(args: argparse.Namespace) -> None:
    """Print what a PLY holds, or without one what this machine runs, as text or JSON."""
    if args.scene is None:
        info = machine_info()
        print(json.dumps(info, indent=2) if args.json else _format_machine(info))
        return
    require_input("scene", args.scene, folder=True)
    info = scene_info(args.scene, drop_invalid=args.drop_invalid)
    print(json.dumps(info, indent=2) if args.json else _format_info(info))


def scene_info(path: Path, *, drop_invalid: bool = False) -> dict[str, Any]:
    """A JSON-ready description of a splat file: its format and what that keeps, header facts (PLY files),
    and statistics of the loaded scene."""
    fmt = detect_format(path)
    header = read_ply_header(path) if fmt in (PLY, COMPRESSED_PLY) else None
    scene = read_scene(path, drop_invalid=drop_invalid)
    return {
        "path": str(path),
        "file_size": _size(path),
        "format": fmt,
        "format_name": FORMATS[fmt].label,
        "encoding": None if header is None else header.format,
        "keeps": FORMATS[fmt].keeps,
        "count": len(scene),
        "sh_degree": scene.sh_degree,
        "normals": all(name in scene.extras for name in NORMAL_NAMES),
        "bounds": _bounds(scene, 1.0),
        "robust_bounds": _bounds(scene, ROBUST_QUANTILE),
        "robust_quantile": ROBUST_QUANTILE,
        "properties": [] if header is None else [{"name": n, "type": t} for n, t in header.properties],
        "extras": list(scene.extras),
        "other_elements": []
        if header is None
        else [{"name": e.name, "count": e.count} for e in header.elements if e.name != "vertex"],
        "comments": [] if header is None else list(header.comments),
    }


def _size(path: Path) -> int:
    """Bytes of a file, or of all files in a folder (an unpacked SOG scene)."""
    return sum(f.stat().st_size for f in path.rglob("*") if f.is_file()) if path.is_dir() else path.stat().st_size


def _bounds(scene: GaussianScene, quantile: float) -> dict[str, list[float]] | None:
    if len(scene) == 0:
        return None
    lo, hi = scene.bounds(quantile)
    return {"min": lo.double().tolist(), "max": hi.double().tolist()}


def _format_machine(info: dict[str, Any]) -> str:
    """The machine description as lines of text: the rasterizer and why first."""
    weights = info["weights"]
    numba = f"{info['numba']} (kernel {'compiled' if info['numba_compiled'] else 'not compiled yet'})"
    return "\n".join(
        [
            f"rasterizer:   {info['rasterizer_label']} ({info['rasterizer_note']})",
            f"C++ compiler: {info['compiler'] or 'not found'}",
            f"numba:        {numba if info['numba'] else 'not installed'}",
            f"kernel cache: {info['kernel_cache']} (C++ kernel {'built' if info['kernel_built'] else 'not built'})",
            f"device:       {info['device']}, {info['threads']} threads, torch {info['torch']}",
            f"precision:    VGG in {info['precision']} with Mixed Precision ({info['precision_note']})",
            f"weights:      {weights.get('weights_file') or weights.get('reason') or 'none found'}",
        ]
    )


def _format_info(info: dict[str, Any]) -> str:
    """The human-readable form of :func:`scene_info`."""
    percent = round(100 * (1 - info["robust_quantile"]))
    rows = [
        ("format", f"{info['format_name']}{_encoding(info)}, {info['file_size'] / 2**20:.1f} MiB"),
        ("keeps", info["keeps"]),
        ("gaussians", f"{info['count']:,}"),
        ("SH degree", str(info["sh_degree"])),
        ("normals", "yes" if info["normals"] else "no"),
        ("bounds", _format_bounds(info["bounds"])),
        (f"robust {percent}-{100 - percent}%", _format_bounds(info["robust_bounds"])),
        *(
            [("properties", f"{len(info['properties'])}: {_compact_properties(info['properties'])}")]
            if info["properties"]
            else []
        ),
        ("extras", " ".join(info["extras"]) or "none"),
    ]
    rows += [("element", f"{e['name']} ({e['count']:,}, skipped)") for e in info["other_elements"]]
    rows += [("comment", c) for c in info["comments"]]
    return "\n".join([info["path"], *(f"  {key:<14}{value}" for key, value in rows)])


def _encoding(info: dict[str, Any]) -> str:
    """`` (binary_little_endian)`` for PLY files, else nothing."""
    return "" if info["encoding"] is None else f" ({info['encoding']})"


def _format_bounds(bounds: dict[str, list[float]] | None) -> str:
    if bounds is None:
        return "none (no Gaussians)"
    return "   ".join(f"{axis} {lo:.4g} .. {hi:.4g}" for axis, lo, hi in zip("xyz", bounds["min"], bounds["max"]))


def _compact_properties(properties: list[dict[str, str]]) -> str:
    """Properties grouped by type with numbered runs folded: 'float: x y z f_dc_0..2 ...'."""
    runs: list[list[Any]] = []  # [prefix or name, first index or None, last index, type]
    for prop in properties:
        match = re.fullmatch(r"(.*_)(\d+)", prop["name"])
        last = runs[-1] if runs else None
        if (
            match
            and last
            and last[1] is not None
            and last[0] == match[1]
            and last[3] == prop["type"]
            and last[2] + 1 == int(match[2])
        ):
            last[2] += 1
        elif match:
            runs.append([match[1], int(match[2]), int(match[2]), prop["type"]])
        else:
            runs.append([prop["name"], None, None, prop["type"]])
    groups: list[tuple[str, list[str]]] = []
    for name, first, last, ply_type in runs:
        label = name if first is None else f"{name}{first}" if first == last else f"{name}{first}..{last}"
        if groups and groups[-1][0] == ply_type:
            groups[-1][1].append(label)
        else:
            groups.append((ply_type, [label]))
    return " | ".join(f"{ply_type}: {' '.join(labels)}" for ply_type, labels in groups)
