"""``info``: what a 3DGS file holds (count, SH degree, bounds, properties), as text or JSON."""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path
from typing import Any

from ...core.scene.gaussians import GaussianScene
from ...core.scene.inria import NORMAL_NAMES
from ...core.scene.ply import read_ply
from ...core.scene.ply_header import read_ply_header
from .args import scene_options

ROBUST_QUANTILE = 0.98
"""Robust bounds ignore the 2 % most extreme means on each side of each axis (as auto_views does)."""


def _add_info(commands: Any, debug: argparse.ArgumentParser) -> None:
    p = commands.add_parser(
        "info",
        parents=[debug, scene_options()],
        help="count, SH degree, bounds and properties of a 3DGS .ply",
        description="Describe a 3D Gaussian Splatting .ply file.",
    )
    p.add_argument("scene", type=Path, metavar="SCENE.ply")
    p.add_argument("--json", action="store_true", help="print the description as JSON")
    p.set_defaults(run=cmd_info)


def cmd_info(args: argparse.Namespace) -> None:
    """Print what a PLY holds, as text or JSON."""
    info = scene_info(args.scene, drop_invalid=args.drop_invalid)
    print(json.dumps(info, indent=2) if args.json else _format_info(info))


def scene_info(path: Path, *, drop_invalid: bool = False) -> dict[str, Any]:
    """A JSON-ready description of a 3DGS PLY: header facts plus statistics of the loaded scene."""
    header = read_ply_header(path)
    scene = read_ply(path, drop_invalid=drop_invalid)
    return {
        "path": str(path),
        "file_size": path.stat().st_size,
        "format": header.format,
        "count": len(scene),
        "sh_degree": scene.sh_degree,
        "normals": all(name in scene.extras for name in NORMAL_NAMES),
        "bounds": _bounds(scene, 1.0),
        "robust_bounds": _bounds(scene, ROBUST_QUANTILE),
        "robust_quantile": ROBUST_QUANTILE,
        "properties": [{"name": name, "type": ply_type} for name, ply_type in header.properties],
        "extras": list(scene.extras),
        "other_elements": [{"name": e.name, "count": e.count} for e in header.elements if e.name != "vertex"],
        "comments": list(header.comments),
    }


def _bounds(scene: GaussianScene, quantile: float) -> dict[str, list[float]] | None:
    if len(scene) == 0:
        return None
    lo, hi = scene.bounds(quantile)
    return {"min": lo.double().tolist(), "max": hi.double().tolist()}


def _format_info(info: dict[str, Any]) -> str:
    """The human-readable form of :func:`scene_info`."""
    percent = round(100 * (1 - info["robust_quantile"]))
    rows = [
        ("format", f"{info['format']}, {info['file_size'] / 2**20:.1f} MiB"),
        ("gaussians", f"{info['count']:,}"),
        ("SH degree", str(info["sh_degree"])),
        ("normals", "yes" if info["normals"] else "no"),
        ("bounds", _format_bounds(info["bounds"])),
        (f"robust {percent}-{100 - percent}%", _format_bounds(info["robust_bounds"])),
        ("properties", f"{len(info['properties'])}: {_compact_properties(info['properties'])}"),
        ("extras", " ".join(info["extras"]) or "none"),
    ]
    rows += [("element", f"{e['name']} ({e['count']:,}, skipped)") for e in info["other_elements"]]
    rows += [("comment", c) for c in info["comments"]]
    return "\n".join([info["path"], *(f"  {key:<14}{value}" for key, value in rows)])


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
