"""Headless texture transfer: ``blender -b --python batch.py -- --ply in.ply --texture tex.jpg --out out.ply``.

Imports the PLY, runs ``gt2gs.transfer_texture`` synchronously, exports the new object, and exits
with 0 on success or 1 with one readable ``gt2gs: error: ...`` line on stderr. Uses the installed
extension when Blender has it enabled, else registers this source tree. Options: ``--preset``,
``--angle`` (degrees), ``--views N`` (automatic views), ``--weights DIR`` (VGG weights folder),
``--allow-fallback-weights`` (write a result made without VGG weights; by default that is an error).

``--manifest jobs.csv --out DIR [--resume]`` runs the jobs of a batch manifest (the one the command line's
``batch`` takes) one after the other, each into its folder in DIR with its report, then the summary table;
a failed job is a row of the table, and the exit status is 1 when any failed.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import json
import math
import os
import sys
import time
from pathlib import Path
from types import ModuleType
from typing import Any

import bpy


def parse_args(argv: list[str]) -> argparse.Namespace:
    """The script's options (after Blender's ``--``), the presets named as the registered extension has them."""
    presets = extension_module("core.transfer.presets")
    parser = argparse.ArgumentParser(prog="blender -b --python batch.py --", description=__doc__.splitlines()[0])
    parser.add_argument("--ply", help="the 3DGS scene (.ply) to re-texture")
    parser.add_argument("--texture", help="the texture photograph")
    parser.add_argument("--out", required=True, help="where to write the re-textured .ply (with --manifest: a folder)")
    parser.add_argument("--manifest", help="a batch manifest (.csv or .toml) of jobs, in place of --ply and --texture")
    parser.add_argument("--resume", action="store_true", help="with --manifest: keep the jobs already done")
    parser.add_argument(
        "--preset",
        default=presets.DEFAULT_PRESET,
        help=f"one of {', '.join(presets.PRESETS)} (default: {presets.DEFAULT_PRESET})",
    )
    parser.add_argument("--angle", type=float, help="texture orientation in the first view, degrees")
    parser.add_argument("--views", type=int, help="number of automatic views (default: the preset's)")
    parser.add_argument("--weights", help="folder with the VGG weights (default: $GT2GS_WEIGHTS_DIR)")
    parser.add_argument(
        "--allow-fallback-weights",
        action="store_true",
        help="write the result even when no VGG weights were found and a random network stood in",
    )
    args = parser.parse_args(argv)
    if (args.manifest is None) == (args.ply is None or args.texture is None):
        parser.error("give --ply and --texture, or --manifest")
    return args


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


def extension_module(name: str) -> ModuleType:
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
    if outcome is not None:
        check_weights(outcome.report, args)
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
    ensure_registered()
    args = parse_args(script_args(sys.argv) if argv is None else argv)
    try:
        with contextlib.redirect_stdout(WithoutErrorEcho(sys.stdout)):
            if args.manifest is not None:
                return run_manifest(args)
            run(args)
    except (RuntimeError, ValueError, OSError, extension_module("core.errors").GT2GSError) as exc:
        sys.stderr.write(f"gt2gs: error: {error_line(exc)}\n")
        return 1
    return 0


class WithoutErrorEcho:
    """A stdout without Blender's echo of an operator's error (``Error: ...``), which the error line says once."""

    def __init__(self, stream: Any) -> None:
        self.stream = stream

    def write(self, text: str) -> int:
        """Pass ``text`` on unless it is an error report (Blender writes each report in one call)."""
        return len(text) if text.startswith("Error: ") else self.stream.write(text)

    def __getattr__(self, name: str) -> Any:
        """Everything else (flush, encoding, ...) is the wrapped stream's."""
        return getattr(self.stream, name)


def error_line(exc: BaseException) -> str:
    """An error as one line, without Blender's 'Error: ' prefix; an OSError names its file."""
    if isinstance(exc, OSError) and exc.filename is not None and exc.strerror:
        return f"{exc.filename}: {exc.strerror}"
    return " ".join(str(exc).strip().removeprefix("Error: ").split())


def run_manifest(args: argparse.Namespace) -> int:
    """Run a manifest's jobs one by one into their folders in ``--out``, write the summary; 1 when any failed."""
    manifest, outputs = extension_module("app.batch.manifest"), extension_module("app.batch.outputs")
    summary = extension_module("app.batch.summary")
    if args.weights:
        os.environ["GT2GS_WEIGHTS_DIR"] = os.path.abspath(args.weights)
    jobs = manifest.read_manifest(args.manifest)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for job, key in zip(jobs, outputs.settings_hashes(jobs)):
        report = outputs.finished(out, job, key) if args.resume else None
        if report is not None:
            rows.append(summary.Row(job, "kept", report=report))
            print(f"gt2gs: kept {job.name} (done before with the same settings)", flush=True)
            continue
        start = time.monotonic()
        try:
            rows.append(summary.Row(job, "done", 1, report=run_job(job, outputs.folder(out, job), key, args)))
        except (RuntimeError, ValueError, OSError, extension_module("core.errors").GT2GSError) as exc:
            rows.append(summary.Row(job, "failed", 1, error=error_line(exc)))
        rows[-1].seconds = time.monotonic() - start
        detail = f": {rows[-1].error}" if rows[-1].error else f" in {rows[-1].seconds:.1f}s"
        print(f"gt2gs: {rows[-1].status} {job.name}{detail}", flush=True)
    for path in summary.write_summary(out, rows):
        print(f"gt2gs: wrote {path}")
    failed = [row for row in rows if row.status == "failed"]
    if failed:
        sys.stderr.write(f"gt2gs: error: {len(failed)} of {len(rows)} jobs failed; see {out / summary.SUMMARY_MD}\n")
    return 1 if failed else 0


def run_job(job: Any, files: Any, key: str, args: argparse.Namespace) -> dict:
    """One manifest job in this Blender: its settings on the scene's panel (the preset's, then the job's), import,
    transfer, export and the report into the job's folder, all or nothing; the report. The objects it made are
    removed after."""
    atomic, properties = extension_module("core.atomic"), extension_module("blender.properties")
    for what, path in (("scene", job.scene), ("texture", job.texture)):
        atomic.require_input(what, path)
        if not os.path.isfile(path):
            raise ValueError(f"{path}: {what} file not found")
    settings = bpy.context.scene.gt2gs
    properties.apply_preset(settings, job.preset)
    settings.preset = job.preset
    for name, value in job.settings.items():
        set_setting(settings, name, value)
    settings.view_source = "CAMERAS_JSON" if job.cameras is not None else "AUTO"
    if job.cameras is not None:
        settings.cameras_json = str(job.cameras)
    settings.result_mode = "NEW"
    before = set(bpy.data.objects)
    try:
        with atomic.all_or_nothing([files.result, files.report], new_folders=[files.path]):
            result, report = transfer_object(job)
            check_weights(report, args)
            with bpy.context.temp_override(active_object=result, object=result, selected_objects=[result]):
                if bpy.ops.gt2gs.export_ply(filepath=str(files.result)) != {"FINISHED"}:
                    raise RuntimeError(f"{files.result}: the export failed")
            report = {**report, "batch": {"job": job.name, "settings_hash": key, "where": job.where}}
            atomic.atomic_write(files.report, json.dumps(report, indent=1, default=str))
    finally:
        for obj in set(bpy.data.objects) - before:
            bpy.data.objects.remove(obj, do_unlink=True)
    return report


def check_weights(report: dict, args: argparse.Namespace) -> None:
    """Refuse a result made by the random stand-in network unless ``--allow-fallback-weights``."""
    if extension_module("panels.transfer_panel").used_fallback(report) and not args.allow_fallback_weights:
        raise RuntimeError(
            "no VGG weights were found, so a random network stood in and the result is not the method's: pass "
            "--weights DIR (or set $GT2GS_WEIGHTS_DIR), or --allow-fallback-weights to write it anyway"
        )


def transfer_object(job: Any) -> tuple[bpy.types.Object, dict]:
    """Import the job's scene and re-texture it with the panel's settings: (result object, report)."""
    bpy.ops.gt2gs.import_ply(filepath=str(job.scene))
    source = bpy.context.view_layer.objects.active
    with bpy.context.temp_override(active_object=source, object=source):
        bpy.ops.gt2gs.transfer_texture(texture_path=str(job.texture))
    result = bpy.context.view_layer.objects.active
    if result is None or result == source:
        raise RuntimeError("the transfer made no result object")
    outcome = extension_module("blender.transfer_run").OUTCOMES.get("transfer")
    return result, dict(outcome.report) if outcome is not None and outcome.report else {}


def set_setting(settings: bpy.types.PropertyGroup, name: str, value: Any) -> None:
    """A job's setting on the scene's panel (angles in radians, as Blender keeps them); a machine setting, which
    Blender keeps in the add-on's preferences, is refused (set it there)."""
    config, setting = extension_module("core.transfer.config"), extension_module("core.transfer.setting")
    meta = config.SETTINGS[name]
    if meta.blender != setting.IN_SCENE:
        raise ValueError(f"{name} is a machine setting, kept in the add-on's preferences: set it there, not per job")
    setattr(settings, name, math.radians(value) if meta.unit == setting.DEGREES else value)


if __name__ == "__main__":
    sys.exit(main())
