"""The ``transfer`` and ``demo`` commands of the command line: run a texture transfer with a progress
bar, write the stylised PLY, the report and a before/after strip."""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path
from typing import Any, Sequence

import cv2
import numpy as np
import torch

from .atomic import atomic_write
from .cameras import Camera, auto_views, load_llff, load_views
from .config import PRESETS, TransferConfig, preset
from .errors import InputFileError
from .ply import read_ply, write_ply
from .rasterizer import render
from .scene import GaussianScene
from .texture import load_texture
from .transfer import Progress, TransferResult, transfer
from .visibility import require_visible

SHARED = Path(__file__).resolve().parents[2].parent / "shared"
DEMO_TEXTURE = SHARED / "data" / "textures" / "herringbone_wood.jpg"
STRIP_VIEWS = 4
STRIP_SIZE = 256


def add_transfer_arguments(p: argparse.ArgumentParser) -> None:
    """Options shared by ``transfer`` and ``demo``: the preset and its overrides."""
    p.add_argument("--preset", choices=tuple(PRESETS), default="fast", help="settings preset (default: fast)")
    p.add_argument("--steps", type=int, metavar="N", help="stylisation steps (default: the preset's)")
    p.add_argument("--resolution", type=int, metavar="PX", help="longest side of the working views")
    p.add_argument("--texture-height", type=int, metavar="PX",
                   help="texture height on the nearest surfaces, in pixels at half the working resolution as the "
                        "feature network sees it (default: the preset's, 256; preview 128); smaller repeats the "
                        "pattern more often")
    p.add_argument("--seed", type=int, help="random seed (default: 0)")
    p.add_argument("--weights", type=Path, metavar="PATH", help="VGG weights file or folder (see README)")
    p.add_argument("--no-color-transfer", dest="color_transfer", action="store_false", default=None,
                   help="skip the colour transfer before and after stylisation")
    p.add_argument("--no-depth-groups", dest="depth_groups", action="store_false", default=None,
                   help="match every feature against all texture scales, not its depth group's")
    p.add_argument("--depth-ratio", type=float, metavar="R",
                   help="how many times smaller the texture shows on the farthest depth group than on the nearest: "
                        "0 = as perspective shows it, measured from the views (the paper; default), at most 2; "
                        "1-16 fixed (the paper's code always uses 2)")
    p.add_argument("--object-backdrop", action="store_true", default=None,
                   help="stylise the object over its own mean colour, not the background, so the texture does not "
                        "trace its outline (dark rims; with --stylise-geometry, halos of splats); weaker texture")
    p.add_argument("--angle", type=float, metavar="DEG",
                   help="orientation control: the texture's angle in the first view, degrees counter-clockwise")
    p.add_argument("--no-gt2", dest="gt2", action="store_false", default=None,
                   help="the paper's NNFM baseline instead of the GT² loss: nearest cells of the texture's own "
                        "feature map, as it lies (no orientations, scales or prior views; --angle has no effect)")
    p.add_argument("--no-afcm", dest="afcm", action="store_false", default=None,
                   help="no adaptive fine-grained control (every feature cell weighs the same)")
    p.add_argument("--no-gpb", dest="gpb", action="store_false", default=None,
                   help="no geometry preservation branch (geometry then learns only from the texture loss, "
                        "with --stylise-geometry, else never)")
    p.add_argument("--stylise-geometry", action=argparse.BooleanOptionalAction, default=None,
                   help="let the texture loss move, scale and turn the splats too, as the paper's code does "
                        "(default: on in the paper presets, else off): bolder texture, looser shape")
    p.add_argument("--no-densify", dest="densify", action="store_false", default=None,
                   help="no densification while stylising")
    p.add_argument("--no-skip-hidden", dest="skip_hidden", action="store_false", default=None,
                   help="optimise every Gaussian, also those no view sees (slower, same result for what is seen)")
    p.add_argument("--no-plateau-stop", dest="plateau_window", action="store_const", const=0, default=None,
                   help="run every step of every phase, also after the loss has stopped falling")
    p.add_argument("--full-matching", dest="match_channels", action="store_const", const=0, default=None,
                   help="match texture features on all channels, not their 64 principal components")
    p.add_argument("--no-mixed-precision", dest="mixed_precision", action="store_false", default=None,
                   help="run VGG in float32 on a CUDA GPU too (default there: float16; the CPU always uses float32)")
    p.add_argument("--threads", type=int, metavar="N",
                   help="CPU threads for the run (default: one per physical core)")
    p.add_argument("--report", type=Path, metavar="R.json", help="write the run's report as JSON")


def add_view_arguments(p: argparse.ArgumentParser) -> None:
    views = p.add_mutually_exclusive_group()
    views.add_argument("--cameras", type=Path, metavar="FILE_OR_DIR",
                       help="cameras.json, poses_bounds.npy, a COLMAP model, or a folder holding one")
    views.add_argument("--llff", type=Path, metavar="DIR", help="an LLFF capture folder (poses_bounds.npy)")
    views.add_argument("--views", type=int, metavar="N", help="N automatic views around the scene")


def config_from_args(args: argparse.Namespace, **extra: Any) -> TransferConfig:
    """The preset with the command line's overrides (options not given keep the preset's value)."""
    weights = args.weights if args.weights is not None else os.environ.get("GT2GS_WEIGHTS_DIR") or _shared_weights()
    return preset(
        args.preset, stylise_steps=args.steps, resolution=args.resolution, texture_height=args.texture_height,
        seed=args.seed, weights_path=str(weights) if weights else None, color_transfer=args.color_transfer,
        depth_groups=args.depth_groups, depth_ratio=args.depth_ratio, object_backdrop=args.object_backdrop,
        background=tuple(args.background), backend=args.backend,
        device=args.device, n_views=getattr(args, "views", None), angle=args.angle, gt2=args.gt2, afcm=args.afcm,
        gpb=args.gpb, stylise_geometry=args.stylise_geometry, densify=args.densify, skip_hidden=args.skip_hidden,
        plateau_window=args.plateau_window, match_channels=args.match_channels, mixed_precision=args.mixed_precision,
        threads=args.threads, **extra,
    )


def _shared_weights() -> Path | None:
    """The project's shared weights folder when it sits beside the checkout (development and CI)."""
    folder = SHARED / "weights"
    return folder if folder.is_dir() else None


def _views(args: argparse.Namespace) -> list[Camera] | None:
    if args.cameras is not None:
        return load_views(args.cameras)
    if args.llff is not None:
        return load_llff(args.llff).cameras
    return None


def _views_source(args: argparse.Namespace) -> str | None:
    """The cameras file or LLFF folder the views come from (None: automatic views), for messages."""
    source = args.cameras if args.cameras is not None else args.llff
    return None if source is None else str(source)


def cmd_transfer(args: argparse.Namespace) -> None:
    """Re-texture a scene, write the stylised PLY (and report, strip), print a summary."""
    scene = read_ply(args.scene, drop_invalid=args.drop_invalid)
    texture = load_texture(args.texture)  # inputs are checked before any work starts
    region = load_region(args.region, len(scene)) if args.region is not None else None
    views, config = _views(args), config_from_args(args)
    require_visible(scene, views, config, args.scene, _views_source(args), region)
    result = run_with_progress(scene, texture, views, config, region)
    write_ply(args.output, result.scene)
    print(f"stylised scene: {args.output}")
    _write_outputs(args.report, args.strip, scene, result, texture)
    print(summary(result.report))


def _write_outputs(report: Path | None, strip: Path | None, original: GaussianScene, result: TransferResult,
                   texture: np.ndarray) -> None:
    if report is not None:
        atomic_write(report, json.dumps(result.report, indent=1, default=str))
        print(f"report: {report}")
    if strip is not None:
        write_before_after(strip, original, result.scene, texture)
        print(f"before/after: {strip}")


def load_region(path: Path, n: int) -> np.ndarray:
    """A region file: a .npy of Gaussian indices, or of n booleans (True = restyle)."""
    try:
        region = np.load(path, allow_pickle=False)
    except (OSError, ValueError) as exc:
        raise InputFileError(path, f"cannot read the region as a .npy array: {exc}") from exc
    if region.dtype == np.bool_:
        if region.shape != (n,):
            raise InputFileError(path, f"a boolean region needs {n} entries (one per Gaussian), has {region.shape}")
    elif not np.issubdtype(region.dtype, np.integer) or region.ndim != 1:
        raise InputFileError(path, f"the region must be a 1-D array of indices or booleans, got {region.dtype} "
                                   f"{region.shape}")
    return region


def run_with_progress(scene: GaussianScene, texture: np.ndarray, views: Sequence[Camera] | None,
                      config: TransferConfig, region: np.ndarray | None = None) -> TransferResult:
    """``transfer`` with a progress bar on stderr (a redrawn bar on a terminal, else a line per stage)."""
    bar = ProgressBar(sys.stderr)
    try:
        return transfer(scene, texture, views, config, region=region, progress=bar)
    finally:
        bar.close()


class ProgressBar:
    """Renders transfer progress: ``[#####.....]  52% stylise 104/200  ETA 0:41``."""

    def __init__(self, stream) -> None:
        self.stream = stream
        self.tty = stream.isatty()
        self.stage = None
        self.last = 0.0

    def __call__(self, p: Progress) -> None:
        if self.tty:
            filled = int(30 * p.fraction)
            eta = "" if p.eta_s is None else f"  ETA {int(p.eta_s) // 60}:{int(p.eta_s) % 60:02d}"
            self.stream.write(f"\r[{'#' * filled}{'.' * (30 - filled)}] {p.fraction:4.0%} {p.stage} "
                              f"{p.step}/{p.total}{eta}   ")
        elif p.stage != self.stage or time.monotonic() - self.last > 30:
            self.stream.write(f"{p.fraction:4.0%} {p.message}\n")
            self.last = time.monotonic()
        self.stage = p.stage
        self.stream.flush()

    def close(self) -> None:
        if self.tty:
            self.stream.write("\n")


def summary(report: dict) -> str:
    """A few lines: time per stage, the feature network (and a loud note on the fallback), the metrics."""
    stages = ", ".join(f"{k} {v:.1f}s" for k, v in report["stage_seconds"].items())
    lines = [f"done in {report['seconds']:.1f}s ({stages}); {report['n_gaussians']:,} Gaussians, "
             f"{report['n_views']} views at {report['image_size'][0]}x{report['image_size'][1]}"]
    weights = report["weights"]
    lines.append(("WARNING, fallback features: " if weights["fallback"] else "features: ") + weights["reason"])
    metrics = report.get("metrics")
    if metrics:
        lines.append("metrics: " + ", ".join(f"{k} {v:.4f}" for k, v in metrics.items() if v is not None))
    return "\n".join(lines)


@torch.no_grad()
def write_before_after(path: Path, original: GaussianScene, stylised: GaussianScene, texture: np.ndarray) -> None:
    """A PNG: the texture, then the original (top) and stylised (bottom) scene from 4 views."""
    cams = auto_views(original, STRIP_VIEWS, width=STRIP_SIZE, height=STRIP_SIZE, elevation_deg=30.0)
    rows = [render(s, cams, background=(1.0, 1.0, 1.0)).colors.clamp(0, 1) for s in (original, stylised)]
    tiles = [torch.cat(list(r), dim=1) for r in rows]
    swatch = torch.from_numpy(cv2.resize(texture, (STRIP_SIZE, STRIP_SIZE), interpolation=cv2.INTER_AREA))
    white = torch.ones_like(swatch)
    image = torch.cat([torch.cat([swatch, tiles[0]], 1), torch.cat([white, tiles[1]], 1)], 0)
    bgr = (image.numpy()[..., ::-1] * 255 + 0.5).astype(np.uint8)
    ok, data = cv2.imencode(".png", bgr)
    if not ok:
        raise OSError(f"{path}: could not encode the PNG")
    atomic_write(path, data.tobytes())
