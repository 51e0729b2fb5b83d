"""Headless texture transfer: ``blender -b --python batch.py -- --ply in.ply --texture tex.jpg --out out.ply``.

Imports the PLY, runs ``gt2gs.transfer_texture`` synchronously, exports the new object, and exits
with 0 on success or 1 with one readable ``gt2gs: error: ...`` line on stderr. Uses the installed
extension when Blender has it enabled, else registers this source tree. Options: ``--preset``,
``--angle`` (degrees), ``--views N`` (automatic views), ``--weights DIR`` (VGG weights folder),
``--allow-fallback-weights`` (write a result made without VGG weights; by default that is an error).
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from pathlib import Path

import bpy


def parse_args(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="blender -b --python batch.py --", description=__doc__.splitlines()[0])
    parser.add_argument("--ply", required=True, help="the 3DGS scene (.ply) to re-texture")
    parser.add_argument("--texture", required=True, help="the texture photograph")
    parser.add_argument("--out", required=True, help="where to write the re-textured .ply")
    parser.add_argument("--preset", default="fast", help="preview, fast or balanced (default: fast)")
    parser.add_argument("--angle", type=float, help="texture orientation in the first view, degrees")
    parser.add_argument("--views", type=int, help="number of automatic views (default: the preset's)")
    parser.add_argument("--weights", help="folder with the VGG weights (default: $GT2GS_WEIGHTS_DIR)")
    parser.add_argument(
        "--allow-fallback-weights",
        action="store_true",
        help="write the result even when no VGG weights were found and a random network stood in",
    )
    return parser.parse_args(argv)


def script_args(argv: list[str]) -> list[str]:
    """The arguments after ``--`` (Blender's own come before it)."""
    return argv[argv.index("--") + 1 :] if "--" in argv else []


def ensure_registered() -> None:
    """Register the extension from this source tree unless Blender already has it enabled."""
    if hasattr(bpy.types, "GT2GS_OT_transfer_texture"):
        return
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    import gt2gs_blender

    gt2gs_blender.register()


def extension_module(name: str):
    """A module of the registered extension (the installed ``bl_ext...`` copy or this source tree)."""
    package = bpy.types.GT2GS_OT_transfer_texture.__module__.rsplit(".operators", 1)[0]
    return importlib.import_module(f"{package}.{name}")


def run(args: argparse.Namespace) -> None:
    """Import, transfer, export; RuntimeError (the operator's report), ValueError or the engine's error on failure."""
    check_paths(args)
    if args.weights:
        os.environ["GT2GS_WEIGHTS_DIR"] = os.path.abspath(args.weights)
    bpy.ops.gt2gs.import_ply(filepath=os.path.abspath(args.ply))
    source = bpy.context.view_layer.objects.active
    overrides = {"texture_path": os.path.abspath(args.texture), "preset": args.preset}
    if args.angle is not None:
        overrides["angle"] = args.angle
    if args.views is not None:
        overrides["n_views"] = args.views
    bpy.context.scene.gt2gs.result_mode = "NEW"
    with bpy.context.temp_override(active_object=source, object=source):
        bpy.ops.gt2gs.transfer_texture(**overrides)
    result = bpy.context.view_layer.objects.active
    if result is None or result == source:
        raise RuntimeError("the transfer made no result object")
    outcome = extension_module("blender.transfer_run").OUTCOMES.get("transfer")
    used_fallback = extension_module("panels.transfer_panel").used_fallback
    if outcome is not None and used_fallback(outcome.report) and not args.allow_fallback_weights:
        raise RuntimeError(
            "no VGG weights were found, so a random network stood in and the result is not the method's: pass "
            "--weights DIR (or set $GT2GS_WEIGHTS_DIR), or --allow-fallback-weights to write it anyway"
        )
    with bpy.context.temp_override(active_object=result, object=result, selected_objects=[result]):
        bpy.ops.gt2gs.export_ply(filepath=os.path.abspath(args.out))
    print(f"gt2gs: wrote {args.out}")


def check_paths(args: argparse.Namespace) -> None:
    """The command line's rules before any work: the inputs are files, the output overwrites none of them and
    can be written."""
    atomic = extension_module("core.atomic")
    inputs = [("scene", args.ply), ("texture", args.texture)]
    for what, path in inputs:
        atomic.require_input(what, path)
        if not os.path.isfile(path):
            raise ValueError(f"{path}: {what} file not found")
    if args.weights:
        atomic.require_input("weights", args.weights, folder=True)
    atomic.check_outputs([("--out", args.out)], [*inputs, ("weights", args.weights)])


def main(argv: list[str] | None = None) -> int:
    """Run the batch job; the exit status (0 ok, 1 failure with one error line)."""
    args = parse_args(script_args(sys.argv) if argv is None else argv)
    ensure_registered()
    try:
        run(args)
    except (RuntimeError, ValueError, extension_module("core.errors").GT2GSError) as exc:
        message = str(exc).strip().removeprefix("Error: ").strip()
        sys.stderr.write(f"gt2gs: error: {message}\n")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
