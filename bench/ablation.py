"""The paper's ablation on our scenes: full GT²-GS vs no GT² loss (NNFM) vs no AFCM vs no GPB, same budget.

``python bench/ablation.py [--scenes donut fern] [--preset fast] [--steps N] [--sh-degree D] [--seeds S]
[--elevation DEG] [--set KEY=VALUE ...] [--json PATH]`` prints a table of SSIM (the paper's, of the whole frame,
and ``object_ssim``, over the object's pixels: how much of the scene is kept), short/long-range RMSE and
LPIPS, texture match, coarse long-range RMSE, time and Gaussian count (with ``--seeds`` > 1 a row per seed,
then each variant's mean and half-range), writes the records to bench/out/ablation.json (or PATH) and a PNG
strip per scene beside them (texture, original, then each variant, 3 views; first seed). ``--set`` changes a
TransferConfig field for every variant: ``--set stylise_geometry=on`` runs the authors' coupled
optimisation, where the GPB has geometry to correct. ``lt_rmse_coarse`` is the long-range RMSE of renders
blurred by 2 px first: on the donut's views 157 degrees apart the depth warp misregisters fine detail, so
the plain RMSE grows with how much detail a result carries. "No GT²" is the paper's NNFM loss (Eq. 1):
nearest cells of the texture's own feature map. Texture match is measured against the labelled bank (every
orientation and scale) for every variant. Every variant runs every step of the preset's schedule (no
loss-plateau stop), so the budgets are equal: a variant without the GPB stylises in one phase, whose plateau
comes at another step count. The donut uses 16 automatic orbit views (``--elevation DEG`` sets the orbit's
elevation, default 20: at 60 the views 157 degrees apart share the donut's top, 20 % of the image instead of
3 %, so long-range consistency weighs real surface); the fern is the shared LLFF capture fitted with the fit
engine (the benchmarks' one cached fit, ``recognise_scenes.fern_fit_dir``) seen from its own cameras. ``--video
K`` also measures consistency the peers' way (StyleGaussian, cited by the paper): on a rendered video, a
smooth path with K frames between consecutive views (closed around the donut's orbit), frames i vs i+1
(video_st) and i vs i+7 (video_lt), which on the donut's 16 views at K = 8 are 2.8 and 20 degrees apart
instead of 22.5 and 157. ``--sh-degree D`` > 0 runs every variant with view-dependent restyled colours
(stylised_sh_degree): the setting of the NNFM baselines, where per-view disagreements can show up as
view-dependent colour, so that long-range consistency can tell the variants apart (at 0 both are consistent
by construction).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import cv2
import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.common import parse_overrides
from bench.recognise_scenes import fern_fit_dir
from gt2gs_blender.core.cameras.camera import Camera
from gt2gs_blender.core.cameras.files import load_views
from gt2gs_blender.core.cameras.generate import auto_views
from gt2gs_blender.core.cameras.poses import camera_path
from gt2gs_blender.core.features.lpips import LPIPS, load_lpips
from gt2gs_blender.core.render import render
from gt2gs_blender.core.scene.gaussians import GaussianScene
from gt2gs_blender.core.scene.ply import read_ply
from gt2gs_blender.core.transfer.gt2 import view_order
from gt2gs_blender.core.transfer.metrics import LONG_RANGE, SHORT_RANGE, consistency
from gt2gs_blender.core.transfer.pipeline import transfer
from gt2gs_blender.core.transfer.presets import preset
from gt2gs_blender.core.transfer.texture import load_texture
from gt2gs_blender.core.transfer.views import fit_cameras

SHARED = ROOT.parent / "shared"
OUT = ROOT / "bench" / "out"
VARIANTS = {
    "full": {},
    "no-GT2": {"gt2": False},
    "no-AFCM": {"afcm": False},
    "no-GPB": {"gpb": False},
}
SCENES = {
    "donut": ("herringbone_wood.jpg", (1.0, 1.0, 1.0)),
    "fern": ("tree_bark.jpg", (0.0, 0.0, 0.0)),
}
STRIP_VIEWS = 3
TILE = 192
METRICS = ("ssim", "object_ssim", "st_rmse", "st_lpips", "lt_rmse", "lt_lpips", "texture_match", "lt_rmse_coarse")
COARSE_SIGMA = 2.0
"""Pixels: the Gaussian blur before ``lt_rmse_coarse``, wider than a depth warp's misregistration across 157 degrees."""
VIDEO_METRICS = ("video_st_rmse", "video_st_lpips", "video_lt_rmse", "video_lt_lpips")


def load_scene(name: str, elevation: float | None = None) -> tuple[GaussianScene, list[Camera] | None]:
    """The scene and its views (None = the transfer's automatic views; the donut's orbit at ``elevation``
    degrees when given: 16 views at 256 px, as the fast preset's own)."""
    if name == "donut":
        donut = read_ply(SHARED / "data" / "scenes" / "donut" / "point_cloud.ply")
        return donut, None if elevation is None else auto_views(
            donut, 16, width=256, height=256, elevation_deg=elevation
        )
    fitted = fern_fit_dir()
    return read_ply(fitted / "point_cloud.ply"), load_views(fitted / "cameras.json")


def run_variant(
    scene: GaussianScene,
    texture: np.ndarray,
    views: list[Camera] | None,
    overrides: dict,
    args: argparse.Namespace,
    background: tuple[float, float, float],
    seed: int,
    video: tuple[list[Camera], LPIPS] | None,
) -> tuple[dict, GaussianScene]:
    config = preset(
        args.preset,
        stylise_steps=args.steps,
        weights_path=str(SHARED / "weights"),
        seed=seed,
        background=background,
        stylised_sh_degree=args.sh_degree,
        plateau_window=0,
        **{**args.overrides, **overrides},
    )
    start = time.perf_counter()
    result = transfer(scene, texture, views, config)
    row = {k: result.report["metrics"][k] for k in METRICS if k in result.report["metrics"]}
    row["lt_rmse_coarse"] = coarse_consistency(
        result.scene, fit_cameras(scene, views, config.resolution, config.n_views), background
    )
    row.update(
        texture_match_start=result.report["metrics"]["texture_match_start"],
        seconds=time.perf_counter() - start,
        n_gaussians=result.report["n_gaussians"],
    )
    if video is not None:
        row.update(video_consistency(result.scene, *video, background))
    return row, result.scene


def coarse_consistency(scene: GaussianScene, cameras: list[Camera], background: tuple[float, float, float]) -> float:
    """Long-range RMSE of the renders blurred by COARSE_SIGMA first: consistency of what the views show,
    without the misregistration of fine detail that a depth warp across distant views leaves behind."""
    out = render(scene, cameras, background=torch.tensor(background))
    blurred = torch.stack(
        [torch.from_numpy(cv2.GaussianBlur(image.clamp(0, 1).numpy(), (0, 0), COARSE_SIGMA)) for image in out.colors]
    )
    return consistency(blurred, out.depths, out.alphas, cameras, LONG_RANGE)["rmse"]


def video_path(scene: GaussianScene, views: list[Camera] | None, frames_per_gap: int, closed: bool) -> list[Camera]:
    """A smooth path through the original scene's views in visiting order (the same for every variant),
    ``closed`` round an orbit."""
    cameras = fit_cameras(scene, views, 256, 16)
    return camera_path([cameras[i] for i in view_order(cameras)], frames_per_gap, closed=closed)


def video_consistency(
    scene: GaussianScene, path: list[Camera], lpips: LPIPS, background: tuple[float, float, float]
) -> dict:
    """``video_{st,lt}_{rmse,lpips}``: consistency of ``scene`` rendered along ``path``."""
    out = render(scene, path, background=torch.tensor(background))
    row = {}
    for prefix, offset in (("video_st", SHORT_RANGE), ("video_lt", LONG_RANGE)):
        scores = consistency(out.colors.clamp(0, 1), out.depths, out.alphas, path, offset, lpips=lpips)
        row[f"{prefix}_rmse"], row[f"{prefix}_lpips"] = scores["rmse"], scores["lpips"]
    return row


def strip(
    texture: np.ndarray, scenes: dict[str, GaussianScene], cameras: list[Camera], background: tuple[float, float, float]
) -> np.ndarray:
    """One row per scene (original, then the variants), one column per view, each row labelled on
    the left; the first label tile shows the texture. uint8 RGB."""
    rows = []
    for i, (name, scene) in enumerate(scenes.items()):
        label = (
            cv2.resize(texture, (TILE, TILE), interpolation=cv2.INTER_AREA)
            if i == 0
            else np.ones((TILE, TILE, 3), np.float32)
        )
        cv2.putText(label, name, (8, TILE - 12), cv2.FONT_HERSHEY_SIMPLEX, 0.7, (0.0, 0.0, 0.0), 2, cv2.LINE_AA)
        tiles = [label] + [
            cv2.resize(
                render(scene, [cam], background=torch.tensor(background)).colors[0].clamp(0, 1).numpy(),
                (TILE, TILE),
                interpolation=cv2.INTER_AREA,
            )
            for cam in cameras
        ]
        rows.append(np.concatenate(tiles, axis=1))
    return (np.concatenate(rows, axis=0) * 255 + 0.5).astype(np.uint8)


def seed_summary(rows: list[dict], metrics: tuple[str, ...]) -> tuple[dict, dict]:
    """Mean and half-range over seeds of every metric, the time and the Gaussian count."""
    keys = (*metrics, "seconds", "n_gaussians")
    values = {k: [r[k] for r in rows if r[k] is not None] for k in keys}
    mean = {k: float(np.mean(v)) if v else None for k, v in values.items()}
    spread = {k: (max(v) - min(v)) / 2.0 if v else None for k, v in values.items()}
    return mean, spread


def print_row(scene: str, label: str, row: dict, metrics: tuple[str, ...]) -> None:
    cells = " ".join(f"{row[m]:>13.4f}" if row[m] is not None else f"{'-':>13}" for m in metrics)
    print(f"{scene:<6} {label:<12} {cells} {row['seconds']:>6.0f} {row['n_gaussians']:>7,.0f}", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="+", choices=tuple(SCENES), default=list(SCENES))
    parser.add_argument("--variants", nargs="+", choices=tuple(VARIANTS), default=list(VARIANTS))
    parser.add_argument("--preset", default="fast")
    parser.add_argument("--steps", type=int, help="stylise steps (default: the preset's)")
    parser.add_argument("--sh-degree", type=int, default=0, help="SH degree of the restyled colours (0-3)")
    parser.add_argument(
        "--video", type=int, default=0, metavar="K", help="also video consistency: K path frames per view gap (0 = off)"
    )
    parser.add_argument(
        "--elevation",
        type=float,
        metavar="DEG",
        help="the donut's orbit elevation (default: the automatic views', 20): at 60 its views "
        "157 degrees apart share the top (20 %% of the image, not 3 %%)",
    )
    parser.add_argument("--seeds", type=int, default=1, help="runs per variant, seeds 0..S-1 (densify and view draws)")
    parser.add_argument(
        "--set",
        nargs="+",
        default=[],
        metavar="KEY=VALUE",
        help="TransferConfig overrides for every variant (typed as the setting: 1, 0.5, true, on)",
    )
    parser.add_argument("--json", type=Path, help="records (default bench/out/ablation[_shD].json)")
    args = parser.parse_args()
    args.overrides = parse_overrides(args.set)
    suffix = f"_sh{args.sh_degree}" if args.sh_degree else ""
    args.json = args.json or OUT / f"ablation{suffix}.json"
    OUT.mkdir(parents=True, exist_ok=True)
    records = []
    metrics = METRICS + (VIDEO_METRICS if args.video else ())
    print(f"{'scene':<6} {'variant':<12} " + " ".join(f"{m:>13}" for m in metrics) + f" {'s':>6} {'N':>7}")
    for scene_name in args.scenes:
        texture_name, background = SCENES[scene_name]
        scene, views = load_scene(scene_name, args.elevation)
        texture = load_texture(SHARED / "data" / "textures" / texture_name)
        results = {"original": scene}
        video = (
            None
            if not args.video
            else (video_path(scene, views, args.video, closed=scene_name == "donut"), load_lpips(SHARED / "weights"))
        )
        for variant in args.variants:
            rows = []
            for seed in range(args.seeds):
                row, result = run_variant(scene, texture, views, VARIANTS[variant], args, background, seed, video)
                results.setdefault(variant, result)
                row.update(
                    scene=scene_name,
                    variant=variant,
                    seed=seed,
                    texture=texture_name,
                    preset=args.preset,
                    sh_degree=args.sh_degree,
                    load=os.getloadavg(),
                )
                rows.append(row)
                print_row(scene_name, variant if args.seeds == 1 else f"{variant}/{seed}", row, metrics)
            records.extend(rows)
            if args.seeds > 1:
                mean, spread = seed_summary(rows, metrics)
                print_row(scene_name, f"{variant} mean", mean, metrics)
                print_row(scene_name, "  ± half", spread, metrics)
        cameras = fit_cameras(scene, views, 256, 16)
        picks = [cameras[i * len(cameras) // STRIP_VIEWS] for i in range(STRIP_VIEWS)]
        png = args.json.with_name(f"{args.json.stem}_{scene_name}.png")
        cv2.imwrite(str(png), cv2.cvtColor(strip(texture, results, picks, background), cv2.COLOR_RGB2BGR))
        print(f"strip: {png}")
    args.json.write_text(json.dumps(records, indent=1))
    print(f"records: {args.json}")


if __name__ == "__main__":
    main()
