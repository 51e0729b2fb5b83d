"""A room seen from inside, given without its cameras: do the automatic views stand where its cameras stood?

    .venv/bin/python bench/room.py [--iterations 2500] [--transfer]

No room capture ships with the project, so this one is made the way a capture is: a textured room (herringbone
floor, brick and woven-straw walls, a plaster ceiling, a toy-brick cabinet in a corner) photographed from inside by
48 cameras standing near its middle and looking out all round, ray-traced exactly, written as an LLFF capture and
fitted by the project's own ``fit`` (3DGS from random points). The splats' sizes then are a trainer's, not made up.
On the fit it prints where ``fitted_viewpoint`` (from the middle, as *Auto* asks) puts the cameras against where they
stood, the gain, whether the capture reads as seen from inside, which views *Automatic Views: Auto* draws, and the
share of each view the room fills from views inside it and from a ring outside it (which sees the walls' backs).
``--transfer`` also re-textures it at ``fast`` from views inside it (*Automatic Views: Inside*) and writes the
before/after strip. Writes bench/out/room/ (JSON, PNGs); the fit is cached.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))
sys.path.insert(0, str(ROOT))

from traced import TEXTURES, Box, Face, fitted_capture, one_look

from gt2gs_blender.app.images import write_png
from gt2gs_blender.core.cameras.camera import Camera
from gt2gs_blender.core.cameras.generate import auto_views, chosen_kind
from gt2gs_blender.core.cameras.poses import look_at
from gt2gs_blender.core.cameras.viewpoint import fitted_viewpoint
from gt2gs_blender.core.render import render
from gt2gs_blender.core.scene.files import read_scene

OUT = ROOT / "bench" / "out" / "room"
ROOM_LO, ROOM_HI = (-2.5, -2.0, 0.0), (2.5, 2.0, 2.6)
"""The room's box (metres, +Z up): 5 x 4 m, 2.6 m high."""
FACES = {
    (2, 0): ("herringbone_wood.jpg", 1.2),
    (2, 1): (None, 1.0),
    (0, 0): ("brick_wall.jpg", 1.5),
    (0, 1): ("brick_wall.jpg", 1.5),
    (1, 0): ("woven_straw.jpg", 1.0),
    (1, 1): ("woven_straw.jpg", 1.0),
}
"""Per (axis, low 0 / high 1) face of the room: its texture (None: plaster) and one repeat's size in metres."""
CABINET = Box((1.6, 1.2, 0.0), (2.5, 2.0, 1.1), one_look("toy_bricks.jpeg", 0.5, (0.7, 0.8, 0.9)))
"""A cabinet in a corner: something that stands before a wall."""
ROOM = Box(
    ROOM_LO,
    ROOM_HI,
    {(axis, high): Face(name, size, 0.75 + 0.1 * axis + 0.05 * high) for (axis, high), (name, size) in FACES.items()},
    shell=True,
)
"""The room's walls, floor and ceiling, seen from inside."""
EYE = np.array([0.2, -0.3, 1.5])
"""Where the cameras stood: near the middle, at eye height."""
VIEWS, WIDTH, HEIGHT, FOV_DEG, DOWNSCALE = 48, 200, 150, 70.0, 8
ITERATIONS = 2500
"""Steps the room is fitted for by default."""


def cameras_inside() -> list[Camera]:
    """``VIEWS`` cameras within 0.3 m of ``EYE``, looking out all round, 5-20 degrees down (full-size intrinsics)."""
    cams = []
    for i in range(VIEWS):
        turn = 2.0 * math.pi * i / VIEWS
        eye = EYE + 0.3 * np.array([math.cos(turn * 3.0), math.sin(turn * 3.0), 0.1 * math.sin(turn * 5.0)])
        down = math.radians(5.0 if i % 2 else 20.0)
        look = np.array([math.cos(turn) * math.cos(down), math.sin(turn) * math.cos(down), -math.sin(down)])
        cams.append(look_at(eye, eye + look, width=WIDTH * DOWNSCALE, height=HEIGHT * DOWNSCALE, fov_deg=FOV_DEG))
    return cams


def fitted_room(iterations: int) -> Path:
    """The cached fit of the room (made and fitted here first when missing)."""
    settings = {"views": VIEWS, "size": [WIDTH, HEIGHT], "eye": EYE.tolist()}
    return fitted_capture(
        "room",
        settings,
        cameras_inside(),
        [ROOM, CABINET],
        size=(WIDTH, HEIGHT),
        downscale=DOWNSCALE,
        iterations=iterations,
    )


def room_share(scene, cams: list[Camera]) -> float:
    """The mean share of the views' pixels the splats cover (alpha above 0.5)."""
    return float(np.mean([(render(scene, [c]).alphas[0] > 0.5).float().mean() for c in cams]))


def contact_sheet(scene, rings: dict[str, list[Camera]], path: Path) -> None:
    """Four views of each ring, one row per ring, over white."""
    rows = []
    for cams in rings.values():
        cells = [render(scene, [c], background=(1.0, 1.0, 1.0)).colors[0].clamp(0, 1).numpy() for c in cams[::4][:4]]
        rows.append(np.concatenate(cells, axis=1))
    write_png(path, (np.concatenate(rows, axis=0) * 255 + 0.5).astype(np.uint8))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--iterations", type=int, default=ITERATIONS)
    parser.add_argument("--transfer", action="store_true", help="also re-texture it at fast (a few minutes)")
    args = parser.parse_args()
    folder = fitted_room(args.iterations)
    scene = read_scene(folder / "fit" / "point_cloud.ply")
    fit = json.loads((folder / "fit" / "fit_report.json").read_text())
    start = time.perf_counter()
    viewpoint = fitted_viewpoint(scene)
    seconds = time.perf_counter() - start
    stood = np.mean([c.center for c in cameras_inside()], axis=0)
    rings = {kind: auto_views(scene, 16, width=128, height=128, kind=kind, up="auto") for kind in ("inside", "orbit")}
    row = {
        "fit": {k: fit[k] for k in ("test_psnr", "test_ssim", "n_gaussians") if k in fit},
        "cameras_stood": stood.tolist(),
        "fitted_point": viewpoint.point.tolist(),
        "metres_off": float(np.linalg.norm(viewpoint.point - stood)),
        "gain": viewpoint.gain,
        "inside": viewpoint.inside,
        "auto_kind": chosen_kind(scene, "auto"),
        "fit_seconds": seconds,
        "room_share": {kind: room_share(scene, cams) for kind, cams in rings.items()},
    }
    print(f"fit: {row['fit']}")
    print(
        f"cameras stood at {np.round(stood, 2)}, fitted {np.round(viewpoint.point, 2)} ({row['metres_off']:.2f} m off)"
    )
    print(f"gain {viewpoint.gain:.3f}, inside {viewpoint.inside}, Auto draws {row['auto_kind']!r} ({seconds:.1f} s)")
    for kind, share in row["room_share"].items():
        print(f"{kind:6s} views: the room covers {share:.0%} of each view")
    OUT.mkdir(parents=True, exist_ok=True)
    contact_sheet(scene, rings, OUT / "views.png")
    if args.transfer:
        row["transfer"] = transfer(folder / "fit" / "point_cloud.ply")
    (OUT / "room.json").write_text(json.dumps(row, indent=1))
    print(f"wrote {OUT / 'room.json'} and {OUT / 'views.png'}")


def transfer(ply: Path) -> dict:
    """The room re-textured at ``fast`` from views inside it (the CLI, as a user runs it): its report."""
    import subprocess

    out = OUT / "room_green_cells.ply"
    command = [
        sys.executable,
        "-m",
        "gt2gs_blender",
        "transfer",
        str(ply),
        str(TEXTURES / "green_cells.jpg"),
        "--out",
        str(out),
        "--preset",
        "fast",
        "--auto-views",
        "inside",
        "--up",
        "+z",
        "--strip",
        str(OUT / "strip.png"),
        "--report",
        str(OUT / "transfer.json"),
    ]
    subprocess.run(command, check=True, cwd=ROOT)
    return json.loads((OUT / "transfer.json").read_text())


if __name__ == "__main__":
    main()
