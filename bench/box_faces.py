"""Does the box layout lie on a boxy capture's sides whichever way its file turns it? *Box Fits Faces* on and off.

    .venv/bin/python bench/box_faces.py [--turns 0 20 45]

The capture is ``bench/camera_side.py``'s ``object-ring``: a toy-brick box on a herringbone slab, ray-traced from a
ring of cameras and fitted by ``fit`` (cached). Its file is turned about up (+Z) by each angle and given the
automatic views a run draws (16 on a ring that starts on the world's +X, fitted to the object). Per turn and
setting: how far the box's right stands from the sides' directions, the share of the sides' visible splats that read
one plane of the box wholly (their largest blend weight above ``ONE_PLANE``), and the contrast black and white bars
keep on the sides once laid on them (0.5 at most; two planes out of step lower it). Prints a table; writes
bench/out/box_faces.json.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))
sys.path.insert(0, str(ROOT))

from camera_side import OBJECT, synthetic

from gt2gs_blender.core.cameras.generate import auto_views
from gt2gs_blender.core.scene.files import read_scene
from gt2gs_blender.core.scene.gaussians import GaussianScene
from gt2gs_blender.core.transfer.faces import faces_direction
from gt2gs_blender.core.transfer.layout import BLEND_POWER, layout_colours, layout_frame, splat_normals
from gt2gs_blender.core.transfer.presets import preset
from gt2gs_blender.core.transfer.views import render_views

OUT = ROOT / "bench" / "out" / "box_faces.json"
ONE_PLANE = 0.9
VIEWS, SIZE = 16, 192
BARS = 8
"""Black and white bar pairs across one texture height."""


def turned_about_z(scene: GaussianScene, degrees: float) -> GaussianScene:
    """``scene`` turned ``degrees`` about +Z through the origin (centres and orientations; colours kept at SH 0)."""
    half = math.radians(degrees) / 2.0
    c, s = math.cos(2 * half), math.sin(2 * half)
    rotation = torch.tensor([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]], dtype=scene.dtype)
    w, z = math.cos(half), math.sin(half)
    q = scene.quats.detach()
    quats = torch.stack(  # (w, 0, 0, z) * q
        [w * q[:, 0] - z * q[:, 3], w * q[:, 1] - z * q[:, 2], w * q[:, 2] + z * q[:, 1], w * q[:, 3] + z * q[:, 0]],
        dim=1,
    )
    return replace(scene.with_sh_degree(0).detach(), means=scene.means.detach() @ rotation.T, quats=quats)


def bars(size: int = 256) -> np.ndarray:
    """Vertical black and white bars, ``BARS`` pairs across."""
    row = ((np.arange(size) * 2 * BARS // size) % 2).astype(np.float32)
    return np.repeat(np.repeat(row[None, :, None], size, axis=0), 3, axis=2)


def side_rows(scene: GaussianScene, degrees: float, normals: torch.Tensor) -> torch.Tensor:
    """The splats on the box's four sides: inside its box (turned back) less a margin from its top, facing sideways."""
    half = math.radians(-degrees)
    c, s = math.cos(half), math.sin(half)
    back = torch.tensor([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    p = scene.means.detach().float() @ back.T
    lo, hi = torch.tensor(OBJECT.lo) - 0.03, torch.tensor(OBJECT.hi) + 0.03
    inside = ((p >= lo) & (p <= hi)).all(dim=1) & (p[:, 2] > 0.1) & (p[:, 2] < OBJECT.hi[2] - 0.1)
    return inside & (normals[:, 2].abs() < 0.5)


def row(scene: GaussianScene, degrees: float, fits: bool) -> dict:
    """One turn and setting's measures (module notes)."""
    turned = turned_about_z(scene, degrees)
    cameras = auto_views(turned, VIEWS, width=SIZE, height=SIZE, up="+z")
    views = render_views(turned, cameras, torch.ones(3), "auto")
    config = preset("fast", box_fits_faces=fits)
    frame = layout_frame(turned, views, config)
    normals = splat_normals(turned, views, frame)
    sides = side_rows(turned, degrees, normals)
    facing = (normals.double() @ torch.from_numpy(frame.axes).T).abs().pow(BLEND_POWER)
    weights = facing / facing.sum(dim=1, keepdim=True).clamp_min(1e-12)
    laid = layout_colours(turned, normals, bars(), frame, 0.0).mean(dim=1)
    heading = math.degrees(math.atan2(frame.axes[0][1], frame.axes[0][0]))
    concentration = faces_direction(views, frame.axes)[1]
    return {
        "turn_deg": degrees,
        "box_fits_faces": fits,
        "right_off_sides_deg": abs((heading - degrees + 45.0) % 90.0 - 45.0),
        "concentration": concentration,
        "side_splats": int(sides.sum()),
        "one_plane_share": float((weights[sides].max(dim=1).values > ONE_PLANE).double().mean()),
        "bar_contrast": float(laid[sides].std()),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--turns", nargs="+", type=float, default=[0.0, 20.0, 45.0])
    args = parser.parse_args()
    ply, _ = synthetic("object-ring")
    scene = read_scene(ply)
    rows = [row(scene, turn, fits) for turn in args.turns for fits in (False, True)]
    print(f"{'turn':>5s} {'fits':>5s} {'off sides':>9s} {'one plane':>9s} {'bars':>6s} {'splats':>7s}")
    for r in rows:
        print(
            f"{r['turn_deg']:5.0f} {'on' if r['box_fits_faces'] else 'off':>5s} {r['right_off_sides_deg']:8.1f}° "
            f"{r['one_plane_share']:9.1%} {r['bar_contrast']:6.3f} {r['side_splats']:7d}"
        )
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(json.dumps({"capture": "object-ring", "views": VIEWS, "size": SIZE, "rows": rows}, indent=1))
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
