"""``render``: a scene to PNGs (and 16-bit depth) from given or generated cameras."""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from ...core.atomic import Named, all_or_nothing, atomic_write, check_outputs, require_input
from ...core.cameras.camera import Camera
from ...core.cameras.cameras_json import save_cameras_json
from ...core.cameras.files import load_views
from ...core.cameras.generate import VIEW_KINDS, auto_views
from ...core.device import resolve_device
from ...core.errors import GT2GSError, InputFileError
from ...core.progress import Progress
from ...core.render import render, resolve_backend
from ...core.scene.files import read_scene
from ...core.scene.gaussians import GaussianScene
from ..images import write_png
from ..progress import TerminalProgress
from .args import add_scene_command, positive_float, positive_int, scene_input, up

BATCH = 4
"""Cameras rendered per rasterizer call: enough to amortise the per-call set-up, little memory."""
VIEWS, WIDTH = 8, 512
"""Generated views: how many, and their width in pixels (square unless --height says otherwise)."""
DEPTH_MIN_ALPHA = 0.1
"""Pixels less opaque than this have no meaningful depth; they are 0 in depth PNGs."""

CAMERAS_FILE, DEPTH_RANGES_FILE = "cameras.json", "depth_ranges.json"


def add_render_command(commands: Any, debug: argparse.ArgumentParser) -> None:
    """The ``render`` subcommand."""
    p = add_scene_command(
        commands,
        debug,
        "render",
        help="render a 3DGS .ply to PNGs",
        description="Render a scene to DIR/view_000.png, ... and write the cameras used to DIR/cameras.json. "
        "Without --cameras, N views on a ring fitted to the scene are generated.",
    )
    p.add_argument("scene", type=Path, metavar="SCENE")
    p.add_argument("-o", "--output", type=Path, required=True, metavar="DIR", help="output folder")
    source = p.add_mutually_exclusive_group()
    source.add_argument(
        "--cameras",
        type=Path,
        metavar="FILE_OR_DIR",
        help="cameras.json, poses_bounds.npy, a COLMAP model, or a folder holding one",
    )
    source.add_argument(
        "--views", type=positive_int, default=VIEWS, metavar="N", help=f"generate N views (default: {VIEWS})"
    )
    p.add_argument("--width", type=positive_int, metavar="W", help=f"generated views' width (default: {WIDTH})")
    p.add_argument("--height", type=positive_int, metavar="H", help="generated views' height (default: W)")
    p.add_argument("--scale", type=positive_float, metavar="F", help="resize --cameras images by F (e.g. 0.25)")
    p.add_argument(
        "--kind",
        choices=VIEW_KINDS,
        default="auto",
        help="generated views: inside where the splats' sizes say the capture was taken from within it, else orbit "
        "(auto); a full ring; a 60° forward-facing arc on -y; a 30° arc on the side the capture was taken from, "
        "read from its splats' sizes where they tell (else the arc); or looking out all round from where the "
        "cameras stood (inside, a room) (default: auto)",
    )
    p.add_argument(
        "--up",
        type=up,
        default="auto",
        metavar="auto|AXIS|X,Y,Z",
        help="the scene's up axis for generated views: auto (the default: estimated from the splats, as transfer "
        "does), +z (Blender's), -y (a 3DGS trainer's capture: write --up=-y), any signed axis or a vector x,y,z",
    )
    p.add_argument("--depth", action="store_true", help="also write 16-bit depth PNGs (DIR/depth_000.png, ...)")
    p.set_defaults(run=cmd_render)


@dataclass
class RenderReport:
    """What a render run produced and how long it took."""

    images: list[Path]
    backend: str
    setup_s: float
    """Backend set-up (the one-time compile of the fast CPU kernel shows here)."""
    render_s: float
    """Rendering and writing the PNGs."""


def cmd_render(args: argparse.Namespace) -> None:
    """Render a scene from given or generated cameras into a folder of PNGs."""
    inputs = scene_input(args.scene)
    if args.cameras is not None:
        require_input("cameras", args.cameras, folder=True)
        inputs.append(("cameras", args.cameras))
    given = _given_cameras(args)
    outputs = render_outputs(args.output, len(given) if given is not None else args.views, args.depth)
    check_outputs(outputs, inputs, new_folders=[args.output])
    scene = read_scene(args.scene, drop_invalid=args.drop_invalid)
    cameras = given if given is not None else _generated_cameras(args, scene)
    with all_or_nothing([path for _, path in outputs], new_folders=[args.output]):
        report = render_to_dir(
            scene,
            cameras,
            args.output,
            background=args.background,
            backend=args.backend,
            device=args.device,
            depth=args.depth,
        )
    print(_summary(report, cameras, args.output))


def render_outputs(out_dir: Path, count: int, depth: bool) -> list[Named]:
    """Every file ``render_to_dir`` writes for ``count`` cameras, named for messages."""
    names = [*(_view_name(i) for i in range(count)), CAMERAS_FILE]
    if depth:
        names += [*(_depth_name(i) for i in range(count)), DEPTH_RANGES_FILE]
    return [(f"the rendered {name}", out_dir / name) for name in names]


def _given_cameras(args: argparse.Namespace) -> list[Camera] | None:
    """The cameras from --cameras (optionally rescaled); None when views are to be generated."""
    if args.cameras is None:
        if args.scale:
            raise GT2GSError("--scale resizes --cameras; for generated views use --width/--height")
        return None
    if args.width or args.height:
        raise GT2GSError("--width/--height size generated views; with --cameras use --scale")
    cameras = load_views(args.cameras)
    return [c.scaled(args.scale) for c in cameras] if args.scale else cameras


def _generated_cameras(args: argparse.Namespace, scene: GaussianScene) -> list[Camera]:
    """Views generated around the scene; an empty one has nothing to place them around."""
    if len(scene) == 0:
        raise InputFileError(args.scene, "holds no splats: there is nothing to place generated views around")
    width = args.width or WIDTH
    return auto_views(scene, args.views, width=width, height=args.height or width, kind=args.kind, up=args.up)


def _view_name(i: int) -> str:
    return f"view_{i:03d}.png"


def _depth_name(i: int) -> str:
    return f"depth_{i:03d}.png"


def render_to_dir(
    scene: GaussianScene,
    cameras: Sequence[Camera],
    out_dir: Path,
    *,
    background: Sequence[float],
    backend: str = "auto",
    device: str = "auto",
    depth: bool = False,
) -> RenderReport:
    """Render ``cameras`` to ``out_dir``/view_###.png (+ depth_###.png) and save them as cameras.json.

    Cameras are rendered in small batches of equal image size; files are numbered in camera order.
    """
    out_dir.mkdir(parents=True, exist_ok=True)
    torch_device = resolve_device(device)
    start = time.perf_counter()
    backend = resolve_backend(backend, torch_device)
    setup_s = time.perf_counter() - start
    scene = scene.to(torch_device)
    images = [out_dir / _view_name(i) for i in range(len(cameras))]
    depth_ranges: dict[str, list[float] | None] = {}
    start = time.perf_counter()
    bar = TerminalProgress("render") if len(cameras) > BATCH else None
    done = 0
    with torch.no_grad():
        for batch in _batches(cameras):
            out = render(scene, [cameras[i] for i in batch], background=background, render_depth=depth, backend=backend)
            for j, i in enumerate(batch):
                write_png(images[i], _to_rgb8(out.colors[j]))
                if depth:
                    encoded, near_far = _encode_depth(out.depths[j], out.alphas[j])
                    write_png(out_dir / _depth_name(i), encoded)
                    depth_ranges[_depth_name(i)] = near_far
            done += len(batch)
            if bar is not None:
                bar(
                    Progress("render", done, len(cameras), done / len(cameras), None, f"rendered {done}/{len(cameras)}")
                )
    if bar is not None:
        bar.close()
    save_cameras_json(out_dir / CAMERAS_FILE, cameras)
    if depth:
        _write_depth_ranges(out_dir / DEPTH_RANGES_FILE, depth_ranges)
    return RenderReport(images, backend, setup_s, time.perf_counter() - start)


def _batches(cameras: Sequence[Camera]) -> Iterator[list[int]]:
    """Camera indices in batches of at most BATCH sharing one image size (sizes in first-seen order)."""
    by_size: dict[tuple[int, int], list[int]] = {}
    for i, camera in enumerate(cameras):
        by_size.setdefault((camera.width, camera.height), []).append(i)
    for indices in by_size.values():
        for start in range(0, len(indices), BATCH):
            yield indices[start : start + BATCH]


def _to_rgb8(rgb: torch.Tensor) -> np.ndarray:
    """(H,W,3) float RGB in 0..1 -> uint8, rounded to nearest."""
    return (rgb.clamp(0.0, 1.0) * 255.0).round().to(torch.uint8).cpu().numpy()


def _encode_depth(depth: torch.Tensor, alpha: torch.Tensor) -> tuple[np.ndarray, list[float] | None]:
    """Surface depth (depth / alpha) as 16 bits: 0 where alpha < DEPTH_MIN_ALPHA, else 1..65535
    linear from the view's nearest to farthest depth; returns the image and [near, far]."""
    valid = alpha >= DEPTH_MIN_ALPHA
    if not bool(valid.any()):
        return np.zeros(tuple(depth.shape), np.uint16), None
    z = depth / alpha.clamp_min(DEPTH_MIN_ALPHA)
    near, far = float(z[valid].min()), float(z[valid].max())
    scaled = 1.0 + (z - near) / max(far - near, 1e-12) * 65534.0
    encoded = torch.where(valid, scaled.clamp(1.0, 65535.0).round(), torch.zeros_like(z))
    return encoded.to(torch.int32).cpu().numpy().astype(np.uint16), [near, far]


def _write_depth_ranges(path: Path, ranges: dict[str, list[float] | None]) -> None:
    doc = {
        "encoding": f"0 = empty (alpha < {DEPTH_MIN_ALPHA}); 1..65535 = near..far, linear in camera z",
        "near_far": ranges,
    }
    atomic_write(path, json.dumps(doc, indent=1))


def _summary(report: RenderReport, cameras: Sequence[Camera], out_dir: Path) -> str:
    sizes = sorted({f"{c.width}x{c.height}" for c in cameras})
    setup = f" + {report.setup_s:.1f} s backend set-up" if report.setup_s >= 1.0 else ""
    return (
        f"rendered {len(cameras)} view(s) at {', '.join(sizes)} to {out_dir}/ "
        f"(backend {report.backend}, {report.render_s:.2f} s{setup})"
    )
