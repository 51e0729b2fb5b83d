"""``demo`` (what ``make demo`` runs): the shared donut and a shared texture, or generated stand-ins
when ``../shared`` is absent. The only code that knows where the project's shared data lives."""

from __future__ import annotations

import argparse
import math
import os
from pathlib import Path
from typing import Any

import numpy as np
import torch

from ...core.atomic import all_or_nothing, check_outputs, require_input
from ...core.features.weights import ENV_VAR
from ...core.scene.files import read_scene
from ...core.scene.gaussians import GaussianScene
from ...core.transfer.texture import load_texture
from ..jobs import run_transfer, summary, write_before_after
from ..progress import TerminalProgress
from .args import add_scene_command, scene_input
from .options import add_setting_arguments, config_from_args
from .transfer import GIVEN, add_views_option

SHARED = Path(__file__).resolve().parents[3].parent / "shared"
"""The project's shared data beside the checkout (development and CI); absent in an installed product."""
SHARED_DONUT = SHARED / "data" / "scenes" / "donut" / "point_cloud.ply"
DEMO_TEXTURE = SHARED / "data" / "textures" / "herringbone_wood.jpg"
SHARED_WEIGHTS = SHARED / "weights"


def add_demo_command(commands: Any, debug: argparse.ArgumentParser) -> None:
    """The ``demo`` subcommand."""
    p = add_scene_command(
        commands,
        debug,
        "demo",
        help="texture-transfer the demo scene (what `make demo` runs)",
        description="Re-texture the shared donut scene with a shared texture (or a generated torus and "
        "stripes when ../shared is absent): writes DIR/stylised.ply, DIR/before_after.png and "
        "DIR/report.json.",
    )
    p.add_argument(
        "--out", type=Path, default=Path("out/demo"), metavar="DIR", help="output folder (default: out/demo)"
    )
    p.add_argument("--scene", type=Path, metavar="SCENE", help="use this scene instead of the donut")
    p.add_argument("--texture", type=Path, metavar="IMAGE", help="use this texture instead of the default")
    add_views_option(p, "number of automatic views (default: the preset's)")
    add_setting_arguments(p, given=GIVEN)
    p.set_defaults(run=cmd_demo)


def cmd_demo(args: argparse.Namespace) -> None:
    """Texture-transfer the demo scene and write the stylised PLY, a before/after strip and the report."""
    scene_path = args.scene or (SHARED_DONUT if SHARED_DONUT.is_file() else None)
    texture = args.texture or (DEMO_TEXTURE if DEMO_TEXTURE.is_file() else None)
    if texture is not None:
        require_input("texture", texture)
    files = [args.out / name for name in ("stylised.ply", "before_after.png", "report.json")]
    check_outputs(
        [(f"--out's {path.name}", path) for path in files],
        [*scene_input(scene_path), ("texture", texture)],
        new_folders=[args.out],
    )
    scene, source = _demo_scene(scene_path, args.drop_invalid)
    image = stripes_texture() if texture is None else load_texture(texture)
    print(f"scene: {source} ({len(scene):,} Gaussians)")
    print(f"texture: {texture or 'generated stripes (the shared textures are absent)'}")
    if args.weights_path is None and not os.environ.get(ENV_VAR) and SHARED_WEIGHTS.is_dir():
        args.weights_path = str(SHARED_WEIGHTS)
    config = config_from_args(args)
    stylised, strip, report = files
    with all_or_nothing(files, new_folders=[args.out]):
        with TerminalProgress("demo") as bar:
            result = run_transfer(scene, image, None, config, stylised, report=report, progress=bar, scene_name=source)
        write_before_after(strip, scene, result.scene, image, None, config.up, config.view_kind)
    print(summary(result.report))
    print(f"wrote {stylised}, {strip} and {report}")


def stripes_texture(size: int = 256, period: int = 24) -> np.ndarray:
    """A generated two-colour diagonal stripe texture (the demo's texture when ../shared is absent)."""
    y, x = np.mgrid[0:size, 0:size]
    band = (((x + y) // (period // 2)) % 2).astype(np.float32)[..., None]
    return band * np.array([0.85, 0.35, 0.1], np.float32) + (1 - band) * np.array([0.95, 0.9, 0.75], np.float32)


def _demo_scene(path: Path | None, drop_invalid: bool) -> tuple[GaussianScene, str]:
    """The scene to show: the given file (or the shared donut), else a generated torus."""
    if path is not None:
        return read_scene(path, drop_invalid=drop_invalid), str(path)
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
