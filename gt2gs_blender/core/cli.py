"""The command line, ``python -m gt2gs_blender``: inspect a 3DGS PLY, render it, run the demo, fit one.

Errors the user can fix (bad files, bad arguments, a job too large for the memory) print one line
on stderr and exit with 2; any other exception is a bug, also reported in one line, with exit code
1; ``--debug`` adds the traceback. Rasterizer warnings (e.g. a backend falling back) are shown as ``gt2gs: warning: ...``.
"""
from __future__ import annotations

import argparse
import contextlib
import json
import logging
import math
import re
import sys
import time
import traceback
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator, Sequence

import cv2
import numpy as np
import torch

from .cameras import Camera, auto_views, load_views, save_cameras_json
from .errors import GT2GSError, out_of_memory_message
from .fit import DEFAULT_POINTS, DEFAULT_SH_DEGREE, FitConfig, FitReport, TextProgress, fit_llff
from .atomic import atomic_write
from .ply import read_ply, read_ply_header, write_ply
from .texture import load_texture
from .rasterizer import BACKENDS, render, resolve_backend
from .scene import GaussianScene
from .visibility import require_visible
from . import transfer_cmd

PROG = "gt2gs"
EXIT_INTERNAL, EXIT_USER = 1, 2
ROBUST_QUANTILE = 0.98
"""Robust bounds ignore the 2 % most extreme means on each side of each axis (as auto_views does)."""
BATCH = 4
"""Cameras rendered per rasterizer call: enough to amortise the per-call set-up, little memory."""
DEPTH_MIN_ALPHA = 0.1
"""Pixels less opaque than this have no meaningful depth; they are 0 in depth PNGs."""
SHARED_DONUT = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "scenes" / "donut" / "point_cloud.ply"


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; return the exit status (0 success, 2 user error, 1 internal error)."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help (0) or a usage error argparse already printed (2)
        return exc.code if isinstance(exc.code, int) else EXIT_USER
    with _reporting_to_stderr():
        try:
            args.run(args)
        except KeyboardInterrupt:
            return _fail(args.debug, "interrupted", 130)
        except (GT2GSError, OSError, ValueError) as exc:
            return _fail(args.debug, _user_message(exc), EXIT_USER)
        except Exception as exc:  # out of memory (the user can ask for less), else a bug: one line unless --debug
            memory = out_of_memory_message(exc)
            if memory is not None:
                return _fail(args.debug, memory, EXIT_USER)
            hint = "" if args.debug else " (run with --debug for the traceback)"
            return _fail(args.debug, f"internal error{hint}: {type(exc).__name__}: {exc}", EXIT_INTERNAL)
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argparse tree: global --debug, then the info / render / demo subcommands."""
    debug = argparse.ArgumentParser(add_help=False)
    debug.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                       help="print the traceback of errors")
    parser = argparse.ArgumentParser(
        prog="python -m gt2gs_blender", allow_abbrev=False,
        description="GT²-GS texture transfer for 3D Gaussian Splatting: command-line tools.")
    parser.add_argument("--debug", action="store_true", help="print the traceback of errors")
    commands = parser.add_subparsers(title="commands", metavar="COMMAND", required=True)
    _add_info(commands, debug)
    _add_render(commands, debug)
    _add_demo(commands, debug)
    _add_fit(commands, debug)
    _add_transfer(commands, debug)
    return parser


# -- argument types ---------------------------------------------------------------------------------


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


# -- subcommand definitions -------------------------------------------------------------------------


def _scene_options() -> argparse.ArgumentParser:
    parent = argparse.ArgumentParser(add_help=False)
    parent.add_argument("--drop-invalid", action="store_true",
                        help="load files with NaN/Inf Gaussians by dropping those Gaussians")
    return parent


def _render_options() -> argparse.ArgumentParser:
    parent = argparse.ArgumentParser(add_help=False)
    group = parent.add_argument_group("rendering")
    group.add_argument("--background", type=_color, default=(1.0, 1.0, 1.0), metavar="R,G,B",
                       help="background colour, components in 0..1 (default: 1,1,1 = white)")
    group.add_argument("--backend", choices=("auto", *BACKENDS), default="auto",
                       help="rasterizer backend (default: auto = the fastest available)")
    group.add_argument("--device", choices=("auto", "cpu", "cuda"), default="auto",
                       help="torch device (default: auto = cuda when available, else cpu)")
    return parent


def _add_info(commands: Any, debug: argparse.ArgumentParser) -> None:
    p = commands.add_parser("info", parents=[debug, _scene_options()],
                            help="count, SH degree, bounds and properties of a 3DGS .ply",
                            description="Describe a 3D Gaussian Splatting .ply file.")
    p.add_argument("scene", type=Path, metavar="SCENE.ply")
    p.add_argument("--json", action="store_true", help="print the description as JSON")
    p.set_defaults(run=cmd_info)


def _add_render(commands: Any, debug: argparse.ArgumentParser) -> None:
    p = commands.add_parser(
        "render", parents=[debug, _scene_options(), _render_options()],
        help="render a 3DGS .ply to PNGs",
        description="Render a scene to DIR/view_000.png, ... and write the cameras used to DIR/cameras.json. "
                    "Without --cameras, N views on a ring fitted to the scene are generated.")
    p.add_argument("scene", type=Path, metavar="SCENE.ply")
    p.add_argument("-o", "--output", type=Path, required=True, metavar="DIR", help="output folder")
    source = p.add_mutually_exclusive_group()
    source.add_argument("--cameras", type=Path, metavar="FILE_OR_DIR",
                        help="cameras.json, poses_bounds.npy, a COLMAP model, or a folder holding one")
    source.add_argument("--views", type=_positive_int, metavar="N", help="generate N views (default: 8)")
    p.add_argument("--width", type=_positive_int, metavar="W", help="generated views' width (default: 512)")
    p.add_argument("--height", type=_positive_int, metavar="H", help="generated views' height (default: W)")
    p.add_argument("--scale", type=_positive_float, metavar="F", help="resize --cameras images by F (e.g. 0.25)")
    p.add_argument("--kind", choices=("orbit", "arc"), default="orbit",
                   help="generated views: a full ring or a 60° forward-facing arc (default: orbit)")
    p.add_argument("--up", type=_up, default=(0.0, 0.0, 1.0), metavar="auto|X,Y,Z",
                   help="the scene's up axis for generated views (default: 0,0,1, Blender's)")
    p.add_argument("--depth", action="store_true", help="also write 16-bit depth PNGs (DIR/depth_000.png, ...)")
    p.set_defaults(run=cmd_render)


def _add_demo(commands: Any, debug: argparse.ArgumentParser) -> None:
    p = commands.add_parser(
        "demo", parents=[debug, _scene_options(), _render_options()],
        help="texture-transfer the demo scene (what `make demo` runs)",
        description="Re-texture the shared donut scene with a shared texture (or a generated torus and "
                    "stripes when ../shared is absent): writes DIR/stylised.ply, DIR/before_after.png and "
                    "DIR/report.json.")
    p.add_argument("--out", type=Path, default=Path("out/demo"), metavar="DIR",
                   help="output folder (default: out/demo)")
    p.add_argument("--scene", type=Path, metavar="SCENE.ply", help="use this scene instead of the donut")
    p.add_argument("--texture", type=Path, metavar="IMAGE", help="use this texture instead of the default")
    p.add_argument("--views", type=_positive_int, metavar="N", help="number of automatic views (default: the preset's)")
    transfer_cmd.add_transfer_arguments(p)
    p.set_defaults(run=cmd_demo)


def _add_transfer(commands: Any, debug: argparse.ArgumentParser) -> None:
    p = commands.add_parser(
        "transfer", parents=[debug, _scene_options(), _render_options()],
        help="re-texture a 3DGS .ply with a texture photo (GT²-GS)",
        description="Re-texture SCENE.ply with TEXTURE so the texture follows the geometry from every view; "
                    "writes the stylised scene to OUT.ply.")
    p.add_argument("scene", type=Path, metavar="SCENE.ply")
    p.add_argument("texture", type=Path, metavar="TEXTURE")
    p.add_argument("-o", "--output", type=Path, required=True, metavar="OUT.ply", help="the stylised scene")
    transfer_cmd.add_view_arguments(p)
    transfer_cmd.add_transfer_arguments(p)
    p.add_argument("--strip", type=Path, metavar="PNG", help="also write a before/after picture")
    p.add_argument("--region", type=Path, metavar="MASK.npy",
                   help="restyle only these Gaussians (.npy of indices or booleans); the rest stay bit-identical")
    p.set_defaults(run=transfer_cmd.cmd_transfer)


def _add_fit(commands: Any, debug: argparse.ArgumentParser) -> None:
    p = commands.add_parser(
        "fit", parents=[debug], help="fit Gaussians to an LLFF capture (3DGS, random initialisation)",
        description="Reconstruct an LLFF capture (poses_bounds.npy + images_N/) from random points with 3DGS: "
                    "every 8th view is held out and scored (PSNR, SSIM); the result is written in the INRIA "
                    "layout (DIR/point_cloud.ply, DIR/point_cloud/iteration_N/point_cloud.ply, DIR/cameras.json).")
    p.add_argument("scene", type=Path, metavar="LLFF_DIR")
    p.add_argument("--out", type=Path, required=True, metavar="DIR", help="output folder")
    p.add_argument("--iterations", type=_positive_int, default=FitConfig.iterations, metavar="N",
                   help=f"optimisation steps (default: {FitConfig.iterations})")
    p.add_argument("--downscale", type=_positive_int, default=8, metavar="F",
                   help="train on images F times smaller than the originals (default: 8)")
    p.add_argument("--points", type=_positive_int, default=DEFAULT_POINTS, metavar="N",
                   help=f"random initial points (default: {DEFAULT_POINTS:,})")
    p.add_argument("--sh-degree", type=int, choices=range(4), default=DEFAULT_SH_DEGREE, metavar="D",
                   help=f"spherical-harmonic degree 0-3 (default: {DEFAULT_SH_DEGREE})")
    p.add_argument("--background", type=_color, default=(0.0, 0.0, 0.0), metavar="R,G,B",
                   help="background colour behind the Gaussians (default: 0,0,0 = black)")
    p.add_argument("--backend", choices=("auto", *BACKENDS), default="auto",
                   help="rasterizer backend (default: auto = the fastest available)")
    p.add_argument("--report", type=Path, metavar="R.json",
                   help="write {test_psnr, test_ssim, seconds, n_gaussians, ...} as JSON")
    p.set_defaults(run=cmd_fit)


# -- info -------------------------------------------------------------------------------------------


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
        "normals": all(name in scene.extras for name in ("nx", "ny", "nz")),
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
        if match and last and last[1] is not None and last[0] == match[1] and last[3] == prop["type"] \
                and last[2] + 1 == int(match[2]):
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


# -- render -----------------------------------------------------------------------------------------


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
    scene = read_ply(args.scene, drop_invalid=args.drop_invalid)
    cameras = _cameras(args, scene)
    report = render_to_dir(scene, cameras, args.output, background=args.background, backend=args.backend,
                           device=args.device, depth=args.depth)
    print(_summary(report, cameras, args.output))


def _cameras(args: argparse.Namespace, scene: GaussianScene) -> list[Camera]:
    """The cameras to render: loaded (optionally rescaled) or generated around the scene."""
    if args.cameras is not None:
        if args.width or args.height:
            raise GT2GSError("--width/--height size generated views; with --cameras use --scale")
        cameras = load_views(args.cameras)
        return [c.scaled(args.scale) for c in cameras] if args.scale else cameras
    if args.scale:
        raise GT2GSError("--scale resizes --cameras; for generated views use --width/--height")
    width = args.width or 512
    return auto_views(scene, args.views or 8, width=width, height=args.height or width, kind=args.kind, up=args.up)


def render_to_dir(
    scene: GaussianScene, cameras: Sequence[Camera], out_dir: Path, *, background: Sequence[float],
    backend: str = "auto", device: str = "auto", depth: bool = False,
) -> RenderReport:
    """Render ``cameras`` to ``out_dir``/view_###.png (+ depth_###.png) and save them as cameras.json.

    Cameras are rendered in small batches of equal image size; files are numbered in camera order.
    """
    out_dir.mkdir(parents=True, exist_ok=True)
    torch_device = _torch_device(device)
    start = time.perf_counter()
    backend = resolve_backend(backend, torch_device)
    setup_s = time.perf_counter() - start
    scene = scene.to(torch_device)
    images = [out_dir / f"view_{i:03d}.png" for i in range(len(cameras))]
    depth_ranges: dict[str, list[float] | None] = {}
    start = time.perf_counter()
    progress = _Progress(len(cameras))
    with torch.no_grad():
        for batch in _batches(cameras):
            out = render(scene, [cameras[i] for i in batch], background=background, render_depth=depth,
                         backend=backend)
            for j, i in enumerate(batch):
                _write_png(images[i], _to_bgr8(out.colors[j]))
                if depth:
                    encoded, near_far = _encode_depth(out.depths[j], out.alphas[j])
                    _write_png(out_dir / f"depth_{i:03d}.png", encoded)
                    depth_ranges[f"depth_{i:03d}.png"] = near_far
            progress.update(len(batch))
    progress.close()
    save_cameras_json(out_dir / "cameras.json", cameras)
    if depth:
        _write_depth_ranges(out_dir / "depth_ranges.json", depth_ranges)
    return RenderReport(images, backend, setup_s, time.perf_counter() - start)


def _torch_device(name: str) -> torch.device:
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name == "cuda" and not torch.cuda.is_available():
        raise GT2GSError(f"--device cuda: CUDA is not available to this torch build ({torch.__version__})")
    return torch.device(name)


def _batches(cameras: Sequence[Camera]) -> Iterator[list[int]]:
    """Camera indices in batches of at most BATCH sharing one image size (sizes in first-seen order)."""
    by_size: dict[tuple[int, int], list[int]] = {}
    for i, camera in enumerate(cameras):
        by_size.setdefault((camera.width, camera.height), []).append(i)
    for indices in by_size.values():
        for start in range(0, len(indices), BATCH):
            yield indices[start:start + BATCH]


def _to_bgr8(rgb: torch.Tensor) -> np.ndarray:
    """(H,W,3) float RGB in 0..1 -> uint8 BGR for OpenCV, rounded to nearest."""
    rgb8 = (rgb.clamp(0.0, 1.0) * 255.0).round().to(torch.uint8).cpu().numpy()
    return np.ascontiguousarray(rgb8[..., ::-1])


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
    doc = {"encoding": f"0 = empty (alpha < {DEPTH_MIN_ALPHA}); 1..65535 = near..far, linear in camera z",
           "near_far": ranges}
    path.write_text(json.dumps(doc, indent=1), encoding="utf-8")


def _write_png(path: Path, image: np.ndarray) -> None:
    """Write a uint8 BGR or uint16 grey PNG (imencode + write_bytes: real OSErrors, any path)."""
    ok, data = cv2.imencode(".png", image)
    if not ok:
        raise OSError(f"{path}: PNG encoding failed")
    path.write_bytes(data.tobytes())


def _summary(report: RenderReport, cameras: Sequence[Camera], out_dir: Path) -> str:
    sizes = sorted({f"{c.width}x{c.height}" for c in cameras})
    setup = f" + {report.setup_s:.1f} s backend set-up" if report.setup_s >= 1.0 else ""
    return (f"rendered {len(cameras)} view(s) at {', '.join(sizes)} to {out_dir}/ "
            f"(backend {report.backend}, {report.render_s:.2f} s{setup})")


class _Progress:
    """A one-line 'rendering k/n' counter on stderr, only on a terminal and for more than one batch."""

    def __init__(self, total: int) -> None:
        self.total, self.done = total, 0
        self.active = total > BATCH and sys.stderr.isatty()

    def update(self, count: int) -> None:
        self.done += count
        if self.active:
            sys.stderr.write(f"\rrendering {self.done}/{self.total}")
            sys.stderr.flush()

    def close(self) -> None:
        if self.active:
            sys.stderr.write("\n")


# -- demo -------------------------------------------------------------------------------------------


def cmd_demo(args: argparse.Namespace) -> None:
    """Texture-transfer the demo scene and write the stylised PLY, a before/after strip and the report."""
    scene, source = _demo_scene(args.scene, args.drop_invalid)
    texture = args.texture or (transfer_cmd.DEMO_TEXTURE if transfer_cmd.DEMO_TEXTURE.is_file() else None)
    print(f"scene: {source} ({len(scene):,} Gaussians)")
    print(f"texture: {texture or 'generated stripes (the shared textures are absent)'}")
    image = stripes_texture() if texture is None else load_texture(texture)
    config = transfer_cmd.config_from_args(args)
    require_visible(scene, None, config, source, None)
    result = transfer_cmd.run_with_progress(scene, image, None, config)
    args.out.mkdir(parents=True, exist_ok=True)
    write_ply(args.out / "stylised.ply", result.scene)
    atomic_write(args.out / "report.json", json.dumps(result.report, indent=1, default=str))
    transfer_cmd.write_before_after(args.out / "before_after.png", scene, result.scene, image)
    print(transfer_cmd.summary(result.report))
    print(f"wrote {args.out / 'stylised.ply'}, {args.out / 'before_after.png'} and {args.out / 'report.json'}")


def stripes_texture(size: int = 256, period: int = 24) -> np.ndarray:
    """A generated two-colour diagonal stripe texture (the demo's texture when ../shared is absent)."""
    y, x = np.mgrid[0:size, 0:size]
    band = (((x + y) // (period // 2)) % 2).astype(np.float32)[..., None]
    return band * np.array([0.85, 0.35, 0.1], np.float32) + (1 - band) * np.array([0.95, 0.9, 0.75], np.float32)


def _demo_scene(path: Path | None, drop_invalid: bool) -> tuple[GaussianScene, str]:
    """The scene to show: the given file, else the shared donut, else a generated torus."""
    if path is not None:
        return read_ply(path, drop_invalid=drop_invalid), str(path)
    if SHARED_DONUT.is_file():
        return read_ply(SHARED_DONUT, drop_invalid=drop_invalid), str(SHARED_DONUT)
    return torus_scene(), f"a generated torus (the shared donut is not at {SHARED_DONUT})"


def torus_scene(n_major: int = 200, n_minor: int = 100, major: float = 1.0, minor: float = 0.4) -> GaussianScene:
    """A procedural torus around +z: n_major x n_minor isotropic Gaussians on a grid, coloured with a
    hue ring around the torus and a checker, so that views differ visibly. Deterministic."""
    u = torch.arange(n_major, dtype=torch.float32) * (2 * math.pi / n_major)
    v = torch.arange(n_minor, dtype=torch.float32) * (2 * math.pi / n_minor)
    uu, vv = (t.reshape(-1) for t in torch.meshgrid(u, v, indexing="ij"))
    ring = major + minor * torch.cos(vv)
    means = torch.stack([ring * torch.cos(uu), ring * torch.sin(uu), minor * torch.sin(vv)], dim=1)
    spacing = max(2 * math.pi * (major + minor) / n_major, 2 * math.pi * minor / n_minor)
    hue = 0.5 + 0.5 * torch.cos(uu[:, None] + torch.tensor([0.0, 2.1, 4.2]))
    checker = ((uu * 12 / math.pi).floor() + (vv * 6 / math.pi).floor()) % 2
    colors = hue * (0.55 + 0.45 * checker[:, None])
    n = len(uu)
    return GaussianScene.from_activated(means, torch.full((n, 3), 0.6 * spacing), torch.full((n,), 0.9), colors)


# -- fit --------------------------------------------------------------------------------------------


def cmd_fit(args: argparse.Namespace) -> None:
    """Fit an LLFF capture, print the held-out scores and time, optionally write a JSON report."""
    config = FitConfig(iterations=args.iterations, background=args.background, backend=args.backend)
    report = fit_llff(args.scene, args.out, downscale=args.downscale, config=config, n_points=args.points,
                      sh_degree=args.sh_degree, progress=TextProgress(sys.stderr))
    if args.report is not None:
        report.write_json(args.report)
    print(_fit_summary(report, args.out))


def _fit_summary(report: FitReport, out_dir: Path) -> str:
    return (f"held-out views ({report.test_views}): PSNR {report.test_psnr:.2f} dB, SSIM {report.test_ssim:.4f}\n"
            f"{report.n_gaussians:,} Gaussians after {report.iterations} iterations on {report.train_views} views; "
            f"{report.seconds:.0f} s in all ({report.train_seconds:.0f} s training)"
            f"{f'; {report.skipped_steps} steps skipped (non-finite loss)' if report.skipped_steps else ''}\n"
            f"wrote {out_dir / 'point_cloud.ply'} and {out_dir / 'cameras.json'}")


# -- error reporting --------------------------------------------------------------------------------


def _user_message(exc: BaseException) -> str:
    """One line for the user; OSErrors name their file."""
    if isinstance(exc, OSError) and exc.filename is not None and exc.strerror:
        message = f"{exc.filename}: {exc.strerror}"
    else:
        message = str(exc) or type(exc).__name__
    return " ".join(message.split())


def _fail(debug: bool, message: str, code: int) -> int:
    if debug:
        traceback.print_exc()
    print(f"{PROG}: error: {' '.join(message.split())}", file=sys.stderr)
    return code


@contextlib.contextmanager
def _reporting_to_stderr() -> Iterator[None]:
    """Show the engine's log warnings and Python warnings as one 'gt2gs: warning:' line each."""
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter(f"{PROG}: warning: %(message)s"))
    handler.setLevel(logging.WARNING)
    logger = logging.getLogger("gt2gs_blender")
    logger.addHandler(handler)

    def show(message: Warning | str, *_: object, **__: object) -> None:
        print(f"{PROG}: warning: {message}", file=sys.stderr)

    try:
        with warnings.catch_warnings():
            warnings.showwarning = show
            yield
    finally:
        logger.removeHandler(handler)
