"""``transfer`` and the options it shares with ``demo``: the preset, its overrides, the views."""
from __future__ import annotations
from .args import _render_options, _scene_options
import argparse
from pathlib import Path
from typing import Any
from ...core.cameras.camera import Camera
from ...core.cameras.llff import load_llff
from ...core.cameras.files import load_views
from ...core.transfer.config import PRESETS, TransferConfig, preset
from ...core.scene.ply import read_ply
from ..jobs import load_region, read_texture, run_transfer, summary, write_before_after
from ..progress import TerminalProgress


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
    return preset(
        args.preset, stylise_steps=args.steps, resolution=args.resolution, texture_height=args.texture_height,
        seed=args.seed, weights_path=None if args.weights is None else str(args.weights), color_transfer=args.color_transfer,
        depth_groups=args.depth_groups, depth_ratio=args.depth_ratio, object_backdrop=args.object_backdrop,
        background=tuple(args.background), backend=args.backend,
        device=args.device, n_views=getattr(args, "views", None), angle=args.angle, gt2=args.gt2, afcm=args.afcm,
        gpb=args.gpb, stylise_geometry=args.stylise_geometry, densify=args.densify, skip_hidden=args.skip_hidden,
        plateau_window=args.plateau_window, match_channels=args.match_channels, mixed_precision=args.mixed_precision,
        threads=args.threads, **extra,
    )


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
    texture = read_texture(args.texture)  # inputs are checked before any work starts
    region = load_region(args.region, len(scene)) if args.region is not None else None
    views, config = _views(args), config_from_args(args)
    with TerminalProgress("transfer") as bar:
        result = run_transfer(scene, texture, views, config, args.output, report=args.report, region=region,
                              progress=bar, scene_name=args.scene, views_name=_views_source(args))
    print(f"stylised scene: {args.output}")
    if args.report is not None:
        print(f"report: {args.report}")
    if args.strip is not None:
        write_before_after(args.strip, scene, result.scene, texture)
        print(f"before/after: {args.strip}")
    print(summary(result.report))


def add_transfer_command(commands: Any, debug: argparse.ArgumentParser) -> None:
    """The ``transfer`` subcommand."""
    p = commands.add_parser(
        "transfer", parents=[debug, _scene_options(), _render_options()],
        help="re-texture a 3DGS .ply with a texture photo (GT²-GS)",
        description="Re-texture SCENE.ply with TEXTURE so the texture follows the geometry from every view; "
                    "writes the stylised scene to OUT.ply.")
    p.add_argument("scene", type=Path, metavar="SCENE.ply")
    p.add_argument("texture", type=Path, metavar="TEXTURE")
    p.add_argument("-o", "--output", type=Path, required=True, metavar="OUT.ply", help="the stylised scene")
    add_view_arguments(p)
    add_transfer_arguments(p)
    p.add_argument("--strip", type=Path, metavar="PNG", help="also write a before/after picture")
    p.add_argument("--region", type=Path, metavar="MASK.npy",
                   help="restyle only these Gaussians (.npy of indices or booleans); the rest stay bit-identical")
    p.set_defaults(run=cmd_transfer)
