"""The scenes of ``bench/recognise.py``: what the transfer optimises, and the held-out views it never saw.

The donut is the shared PLY: the transfer uses its automatic ring (the preset's ``n_views`` at 20 degrees
elevation, first view at azimuth 0); the held-out views are a ring at 40 degrees elevation whose azimuths
fall between the transfer's. The fern is the shared LLFF capture fitted with the project's ``fit`` engine,
once, cached under ``~/.cache/gt2gs_blender/bench/`` by the fit settings; the transfer uses the LLFF
training poses and the held-out views are the LLFF test poses (every 8th), which neither the fit nor the
transfer saw. The captures (a guitar on its stand, 90,854 splats; a robot on a patch of ground, 500,000 splats,
CC-BY-4.0) are seen as the donut is, about their own up axis.

``run_start``/``layout_start``: what a run on a scene starts from, from the engine's own pieces (the pipeline's
prepare stage): the layout's frame from the run's views, and the scene with the texture laid out before any
optimisation step, to render from the held-out views. ``layout_surface``: the same layout on an exact surface
(no splats): the layout free of the splats' blur, alone or over the scene the run keeps (the run's own target).
"""

from __future__ import annotations

import hashlib
import json
import os
import sys
from dataclasses import dataclass, replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import numpy as np
import torch
from recognise_measure import MASK_ALPHA

from gt2gs_blender.core.api import Camera, GaussianScene, TransferConfig, auto_views, load_views, read_scene
from gt2gs_blender.core.cameras.warp import expected_depth
from gt2gs_blender.core.fit.trainer import DEFAULT_POINTS, DEFAULT_SH_DEGREE, LLFF_HOLDOUT, FitConfig, fit_llff
from gt2gs_blender.core.transfer.layout import (
    bright_images,
    layout_images,
    layout_materials,
    layout_shading,
    scene_colour_mix,
    seen_images,
    shade_width,
)
from gt2gs_blender.core.transfer.orientation_preview import laid_out_start
from gt2gs_blender.core.transfer.plan import RunPlan, plan_run, run_texture
from gt2gs_blender.core.transfer.shade import laid_exposure
from gt2gs_blender.core.transfer.views import ViewSet, render_views

SHARED = ROOT.parent / "shared"
DONUT = SHARED / "data" / "scenes" / "donut" / "point_cloud.ply"
FERN = SHARED / "data" / "scenes" / "fern_llff"
CAPTURES = {
    "guitar": SHARED / "data" / "scenes" / "captures" / "guitar.compressed.ply",
    "playbot": SHARED / "data" / "scenes" / "captures" / "playbot",  # CC-BY-4.0: credit in its CREDITS.txt
}
"""Real captures, trained the usual way (up along -y): the transfer uses its automatic ring (``up`` auto finds -y),
the held-out views are from a ring at 40 degrees as the donut's, the four that see the most of it (``broadest``)."""
CAPTURE_UP = "-y"
CAPTURE_SCALE = 2
"""The captures' held-out views are this many times the bench size: a guitar fills a fifth of a square view."""
SCENES = ("donut", "fern", "fern_alone", *CAPTURES)
"""``fern_alone``: the fern given without its cameras (the run's automatic views), judged from its LLFF test poses."""
CACHE = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "gt2gs_blender" / "bench"
FERN_FIT = {"iterations": 1500, "downscale": 8, "points": DEFAULT_POINTS, "sh_degree": DEFAULT_SH_DEGREE, "seed": 0}
"""The fern's fit settings, shared by bench/recognise.py and bench/ablation.py (1,500 steps: ~7 min, once)."""
HELD_OUT_ELEVATION = 40.0
HELD_OUT_RING = 32
HELD_OUT_DONUT = (1, 9, 17, 25)
"""Of a 32-view ring at 40 degrees: azimuths 11.25, 101.25, 191.25, 281.25, between the transfer's 16 (22.5 apart)."""


@dataclass
class BenchScene:
    name: str
    scene: GaussianScene
    transfer_views: list[Camera] | None
    """Cameras the transfer optimises (None = its automatic ring)."""
    held_out: list[Camera]
    background: tuple[float, float, float]


def fern_fit_dir(settings: dict | None = None) -> Path:
    """The cached fern fit for ``settings`` (FERN_FIT by default), fitted here first when missing."""
    settings = {**FERN_FIT, **(settings or {})}
    key = hashlib.sha1(json.dumps(settings, sort_keys=True).encode()).hexdigest()[:12]
    folder = CACHE / f"fern-{key}"
    if not (folder / "point_cloud.ply").is_file():
        print(f"fitting the fern ({settings}) into {folder} (once)", flush=True)
        report = fit_llff(
            FERN,
            folder,
            downscale=settings["downscale"],
            config=FitConfig(iterations=settings["iterations"], seed=settings["seed"]),
            n_points=settings["points"],
            sh_degree=settings["sh_degree"],
        )
        report.write_json(folder / "fit_report.json")
        (folder / "fit_settings.json").write_text(json.dumps(settings, indent=1))
    return folder


def load_bench_scene(name: str, resolution: int = 256) -> BenchScene:
    """One of ``SCENES`` with its transfer views and held-out views (longest side ``resolution``)."""
    if name == "donut" or name in CAPTURES:
        scene = read_scene(CAPTURES.get(name, DONUT))
        up, size = (CAPTURE_UP, resolution * CAPTURE_SCALE) if name in CAPTURES else ("+z", resolution)
        ring = auto_views(scene, HELD_OUT_RING, width=size, height=size, elevation_deg=HELD_OUT_ELEVATION, up=up)
        held_out = [ring[i] for i in (HELD_OUT_DONUT if name == "donut" else broadest(scene, ring))]
        return BenchScene(name, scene, None, held_out, (1.0, 1.0, 1.0))
    if name in ("fern", "fern_alone"):
        folder = fern_fit_dir()
        cameras = load_views(folder / "cameras.json")
        train = [c for i, c in enumerate(cameras) if i % LLFF_HOLDOUT] if name == "fern" else None
        test = [c.scaled(resolution / max(c.width, c.height)) for i, c in enumerate(cameras) if not i % LLFF_HOLDOUT]
        return BenchScene(name, read_scene(folder / "point_cloud.ply"), train, test, (0.0, 0.0, 0.0))
    raise ValueError(f"unknown scene {name!r}; choose one of {', '.join(SCENES)}")


def broadest(scene: GaussianScene, ring: list[Camera]) -> list[int]:
    """Of the ring's views between a 16-view transfer ring's (odd indices), the ``len(HELD_OUT_DONUT)`` that see
    the most of the object, in ring order: a thin capture (a guitar) seen edge-on has no window to measure."""
    between = range(1, len(ring), 2)
    with torch.no_grad():
        seen = {i: float(render_views(scene, [ring[i]], torch.ones(3), "auto").alphas[0].sum()) for i in between}
    return sorted(sorted(seen, key=seen.__getitem__, reverse=True)[: len(HELD_OUT_DONUT)])


def run_start(bench: BenchScene, config: TransferConfig, texture: Path) -> RunPlan:
    """The plan of a run with ``config`` on ``bench`` (the engine's own ``plan_run``, as a preview plans it: the
    views are rendered only when the layout or ``texture_repeats`` needs them)."""
    return plan_run(bench.scene, texture, bench.transfer_views, config, preview=True)


def layout_start(run: RunPlan, texture: Path) -> GaussianScene:
    """The layout a run with ``layout`` on lays, without the optimisation's changes: the texture on the
    splats the run restyles, split to its detail (hidden ones keep their colours, as the result keeps them)."""
    assert run.content is not None and run.frame is not None and run.config.layout
    return laid_out_start(replace(run, texture=run_texture(texture, run.config)))


@torch.no_grad()
def layout_surface(
    run: RunPlan, bench: BenchScene, texture: Path, shaded: bool = False, views: ViewSet | None = None
) -> list[tuple[np.ndarray, np.ndarray]]:
    """(RGB uint8 over the background, alpha) per held-out view: the layout as an exact surface shows it there
    (``layout_images`` on the original scene's depth, no splats, the run's softened texture): the layout free of
    the splats' blur, over every pixel the measure counts (``measured``). A run's texture loss can draw the lines
    sharper than this flat layout (at today's default the fern's run finds a texture more than its surface).
    ``shaded``: over the scene as the run's layout keeps it (Keep Scene, Scene Colour, Scene Brightness), the
    image the layout term holds each view to: the run's own target, free of the splats. ``views``: the scene's
    :func:`surface_views` for ``run``, rendered once for many textures (None: rendered here)."""
    assert run.frame is not None and run.config.layout
    config, photo = run.config, run_texture(texture, run.config)
    views = surface_views(bench, config.backend) if views is None else views
    bright, parts = layout_materials(run.work, run.region, config) if shaded else (None, None)
    mix = scene_colour_mix(run.work, run.region, config)
    kept = layout_shading(run.work, run.region, run.frame, config, photo, mix, bright, parts) if shaded else None
    exposure = 1.0 if kept is None else laid_exposure(kept, run.region)
    lit = None if bright is None else bright_images(run.work, views, bright, config.backend)
    hues = None if parts is None else seen_images(run.work, views, parts, config.backend)
    laid = layout_images(
        views,
        photo,
        run.frame,
        config.angle,
        kept is not None,
        shade_width(run.frame, config),
        config.keep_scene,
        mix,
        exposure,
        lit,
        hues,
    )
    out = []
    for image in laid:
        rgb, alpha = image[..., :3].cpu().numpy(), image[..., 3].cpu().numpy()
        over = rgb * alpha[..., None] + (1.0 - alpha[..., None]) * np.asarray(bench.background, np.float32)
        out.append(((over.clip(0.0, 1.0) * 255 + 0.5).astype(np.uint8), alpha))
    return out


@torch.no_grad()
def surface_views(bench: BenchScene, backend: str) -> ViewSet:
    """The original scene's held-out views as :func:`layout_surface` lays the texture on them (``measured``): the
    same for every texture of a scene."""
    background = torch.tensor(bench.background, dtype=torch.float32)
    return measured(render_views(bench.scene.detach(), bench.held_out, background, backend))


def measured(views: ViewSet) -> ViewSet:
    """``views`` opaque wherever the measure counts a pixel (alpha above ``MASK_ALPHA``) and empty elsewhere, at
    the same surface depth: the layout's own surfaces stop at alpha 0.9, and a ceiling measured over those alone
    left out the semi-transparent pixels (a tenth of the coarse fern's) that a result is judged on."""
    covered = [a > MASK_ALPHA for a in views.alphas]
    return replace(
        views,
        alphas=[c.to(a) for c, a in zip(covered, views.alphas)],
        depths=[expected_depth(d, a, MASK_ALPHA) * c for c, d, a in zip(covered, views.depths, views.alphas)],
        premultiplied=[
            torch.where(c[..., None], p / a.clamp_min(MASK_ALPHA)[..., None], 0.0)
            for c, p, a in zip(covered, views.premultiplied, views.alphas)
        ],
    )


if __name__ == "__main__":
    print(fern_fit_dir())
