"""``fit``: reconstruct an LLFF capture with 3DGS and report held-out PSNR/SSIM."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from ...core.atomic import Named, all_or_nothing, check_outputs, require_input
from ...core.fit.trainer import DEFAULT_POINTS, DEFAULT_SH_DEGREE, FitConfig, FitReport, fit_llff, inria_files
from ..progress import TerminalProgress
from .args import positive_int, render_options


def add_fit_command(commands: Any, debug: argparse.ArgumentParser) -> None:
    """The ``fit`` subcommand."""
    p = commands.add_parser(
        "fit",
        parents=[debug, render_options(background=(0.0, 0.0, 0.0), device=False)],
        help="fit Gaussians to an LLFF capture (3DGS, random initialisation)",
        description="Reconstruct an LLFF capture (poses_bounds.npy + images_N/) from random points with 3DGS: "
        "every 8th view is held out and scored (PSNR, SSIM); the result is written in the INRIA "
        "layout (DIR/point_cloud.ply, DIR/point_cloud/iteration_N/point_cloud.ply, DIR/cameras.json).",
    )
    p.add_argument("scene", type=Path, metavar="LLFF_DIR")
    p.add_argument("--out", type=Path, required=True, metavar="DIR", help="output folder")
    p.add_argument(
        "--iterations",
        type=positive_int,
        default=FitConfig.iterations,
        metavar="N",
        help=f"optimisation steps (default: {FitConfig.iterations})",
    )
    p.add_argument(
        "--downscale",
        type=positive_int,
        default=8,
        metavar="F",
        help="train on images F times smaller than the originals (default: 8)",
    )
    p.add_argument(
        "--points",
        type=positive_int,
        default=DEFAULT_POINTS,
        metavar="N",
        help=f"random initial points (default: {DEFAULT_POINTS:,})",
    )
    p.add_argument(
        "--sh-degree",
        type=int,
        choices=range(4),
        default=DEFAULT_SH_DEGREE,
        metavar="D",
        help=f"spherical-harmonic degree 0-3 (default: {DEFAULT_SH_DEGREE})",
    )
    p.add_argument(
        "--report", type=Path, metavar="R.json", help="write {test_psnr, test_ssim, seconds, n_gaussians, ...} as JSON"
    )
    p.set_defaults(run=cmd_fit)


def cmd_fit(args: argparse.Namespace) -> None:
    """Fit an LLFF capture, print the held-out scores and time, optionally write a JSON report."""
    require_input("LLFF folder", args.scene, folder=True)
    outputs, folders = fit_outputs(args.out, args.iterations, args.report)
    check_outputs(outputs, [("LLFF folder", args.scene)], new_folders=folders)
    config = FitConfig(iterations=args.iterations, background=args.background, backend=args.backend)
    with all_or_nothing([path for _, path in outputs], new_folders=folders), TerminalProgress("fit") as bar:
        report = fit_llff(
            args.scene,
            args.out,
            downscale=args.downscale,
            config=config,
            n_points=args.points,
            sh_degree=args.sh_degree,
            progress=bar,
        )
        if args.report is not None:
            report.write_json(args.report)
    print(_fit_summary(report, args.out))


def fit_outputs(out_dir: Path, iterations: int, report: Path | None) -> tuple[list[Named], list[Path]]:
    """The files ``fit`` writes (the INRIA layout, the report) and the folders it makes for them."""
    files = inria_files(out_dir, iterations)
    outputs = [(f"--out's {path.relative_to(out_dir)}", path) for path in files]
    return outputs + ([("--report", report)] if report is not None else []), [out_dir, files[0].parent]


def _fit_summary(report: FitReport, out_dir: Path) -> str:
    return (
        f"held-out views ({report.test_views}): PSNR {report.test_psnr:.2f} dB, SSIM {report.test_ssim:.4f}\n"
        f"{report.n_gaussians:,} Gaussians after {report.iterations} iterations on {report.train_views} views; "
        f"{report.seconds:.0f} s in all ({report.train_seconds:.0f} s training)"
        f"{f'; {report.skipped_steps} steps skipped (non-finite loss)' if report.skipped_steps else ''}\n"
        f"wrote {out_dir / 'point_cloud.ply'} and {out_dir / 'cameras.json'}"
    )
