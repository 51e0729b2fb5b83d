"""Issue 19's structure benchmark: would a user recognise the texture on their splat?

``python bench/recognise.py [--scenes donut fern] [--textures NAME ...] [--presets fast] [--set KEY=VALUE ...]
[--seeds 0] [--tag TAG] [--only-measure] [--reuse [--reuse-older]]``

For each structured texture and scene, a transfer runs (the named preset plus ``--set`` overrides, each seed);
the result is rendered from held-out views the transfer never optimised (bench/recognise_scenes.py), and all
ten shared textures are ranked by a structure-only distance to those renders under two unlike measures
(bench/recognise_measure.py: VGG-16 relu1_2/relu2_2 Gram matrices and a Gabor bank; grey, on the object's
pixels, best over texture scales and rotations). Rank 1 = the transferred texture is the closest of the ten.

Calibration, in every run (and alone with ``--only-measure``, seconds per scene): the texture alone, nothing of
the scene kept, projected onto the object in screen space (``projected``: texture heights ``--projected-heights``
at the preset's resolution) must rank near the top, and the original untransferred scene must not (the null
case). With ``layout`` on, a ``layout-start`` row too: the scene with the texture laid out exactly as the run
starts from it (before any optimisation), rendered from the held-out views (with several presets,
``<preset>-layout-start``), a ``layout-target`` row: that layout on an exact surface, no splats, over the scene as
the run keeps it (``layout_surface(shaded=True)``: the images the run's layout term holds its views to, free of the
splats' blur), and a ``layout-surface`` row: the texture alone on that surface, nothing of the scene kept. Between
them they say where a texture is lost: to the scene the run keeps (surface -> target), to the splats (target ->
start), or by the optimisation (start -> result; a run's texture loss can also draw the lines sharper).

From the preview: every result's held-out renders are compared image to image with the preview of the same
views (``recognise_measure.pair_distance``: window by window, both measures, no scale or rotation search),
``preview_gram`` / ``preview_gabor`` in the rows; ``original_preview_*`` is the same distance for the
untransferred scene, for scale (a result nearer its preview than the original is keeps what the preview
promised). The preview is the layout start when ``layout`` is on, else the screen-space sketch the run's preview
shows (``orientation_preview.sketch``: its texture size, depth groups and kept scene; a ``sketch`` row);
``preview_reference`` names it.

Each row's ``gram_margin`` / ``gabor_margin`` say how far its texture stands inside (> 0) or outside the top 3
(``recognise_measure.margin_of``: a share of the threshold's distance); the table's "edge" is the smaller, the one
that decides "found", and each summary names the texture nearest to flipping ("nearest flip"): the fern's woven
straw at `balanced` lies 0.1-0.5 % from it, within what float32 rounding moves (docs/quality_log.md, session 42).

Beside the ranks, every row with renders reports ``content_ssim`` ("scene SSIM"): the luminance SSIM of its held-out
views to the original scene's, on the object's pixels: how much of the user's scene still shows under the texture
(the structure measures reward the texture alone; this is the other side of the trade). The original row is 1 by
definition; ``layout-surface`` rows are unshaded (``layout_images`` without the shade), and they and
``layout-target`` rows cover every pixel the measure counts. ``colour_specks`` ("specks") is the share of the
object's pixels whose hue stands out from their neighbourhood: colour noise a run adds (the original row holds the
scene's own: sprinkles, flowers). ``accent_shift`` ("accents") is how far the original's small, vivid features (a
robot's eyes, sprinkles) moved in colour (Lab a, b; NaN where a scene has none). ``part_hues`` ("hues") is whether
the parts keep their hues apart at the object's scale (1: as in the original, whatever tint the texture gives the
whole; 0: one hue for all). ``hue_drift`` ("drift") is how far the optimisation moved the hues from the run's start
(Lab a, b; 0 where its steps only lightened or darkened): patches of a hue neither the texture nor the scene has.
``own_hue`` ("own") is the part of that drift off the way from the start's hue back to the original's, which the
layout term allows for free: a hue of the run's own.

Results are saved per (tag, scene, texture, preset, seed) under bench/out/recognise/<tag>/<scene>/ with the
settings they ran with and the run's stage times, step counts and metrics; ``--reuse`` measures them again
instead of transferring when the settings match (and ``--reuse-older`` also when the saved settings predate
some of today's settings, listed in the row).

Writes bench/out/recognise/<tag>.json (a tag can be filled one scene at a time: the scenes an earlier run under it
measured with the same settings stay, and other settings are refused) and a contact sheet per scene,
bench/out/recognise/<tag>-<scene>.png
(rows: textures; columns: texture | projected | layout start | original | each result's held-out views), and every
held-out view of the original, the layout starts and the results as PNGs under bench/out/recognise/<tag>/<scene>/
(bench/quality_figure.py draws docs/quality.md's picture from them). The target the engine must meet: top 3 under
both measures for at least 5 of the 6 textures on each scene.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import torch
import torch.nn.functional as F

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))
sys.path.insert(0, str(ROOT))

import recognise_measure as measure
from common import parse_overrides
from recognise_scenes import (
    SCENES,
    BenchScene,
    layout_start,
    layout_surface,
    load_bench_scene,
    run_start,
    surface_views,
)

from gt2gs_blender.core.api import GaussianScene, TransferConfig, preset, read_scene, render, transfer, write_ply
from gt2gs_blender.core.atomic import atomic_write
from gt2gs_blender.core.transfer.metrics import OBJECT_BLUR, object_ssim
from gt2gs_blender.core.transfer.orientation_preview import orientation_preview, sketch
from gt2gs_blender.core.transfer.plan import RunPlan, run_texture
from gt2gs_blender.core.transfer.views import ViewSet

SHARED = ROOT.parent / "shared"
TEXTURES = SHARED / "data" / "textures"
OUT = ROOT / "bench" / "out" / "recognise"
HELD_OUT_SIZE = 256
"""The held-out views' longest side the target is judged at (``--size`` measures at another)."""
STRUCTURED = ("herringbone_wood", "brick_wall", "honeycomb", "toy_bricks", "woven_straw", "green_cells")
MEASURES = ("gram", "gabor")
TOP = 3
NEEDED = 5
SUMMED = (
    "preview_gram",
    "preview_gabor",
    "original_preview_gram",
    "original_preview_gabor",
    "content_ssim",
    "colour_specks",
    "accent_shift",
    "part_hues",
    "hue_drift",
    "own_hue",
    "splats",
)
"""The row fields a summary averages per scene and variant."""
Views = list[tuple[np.ndarray, np.ndarray]]
"""(RGB uint8, alpha) per held-out view."""
SPECK_WINDOW = 5
SPECK_CHROMA = 0.06
"""A chroma step a viewer sees as a dot of another hue (the woven straw's magenta dots: ~0.2)."""
ACCENT_CHROMA = 25.0
ACCENT_APART = 20.0
ACCENT_WINDOW = 21
"""An accent pixel: chroma over 25 Lab units, its (a, b) over 20 from its 21 px neighbourhood's median."""
HUE_FLOOR = 2.0
"""``part_hues``: Lab (a, b) units, about one just-noticeable difference: hue differences between parts within this
count as none (a scene of one hue has nothing to keep, and a texture's faint tint does not count against it)."""
HUE_DRIFT_BLUR = 1.0 / 256.0
"""``hue_drift``: the blur (a share of the view's longest side, 1 px at 256) under which a patch of hue counts and
a texture's own finest colour steps mostly do not."""
TILE = 160
SHEET_VIEWS = 2
"""Held-out views per result on the contact sheet."""


# ---------------------------------------------------------------------------------------------------
# Settings
# ---------------------------------------------------------------------------------------------------
def texture_path(name: str) -> Path:
    found = sorted(TEXTURES.glob(f"{name}.*"))
    if not found:
        raise SystemExit(f"no texture {name!r} in {TEXTURES}")
    return found[0]


# ---------------------------------------------------------------------------------------------------
# Renders and their distances
# ---------------------------------------------------------------------------------------------------
@torch.no_grad()
def held_out_renders(scene: GaussianScene, bench: BenchScene) -> list[tuple[np.ndarray, np.ndarray]]:
    """(RGB uint8 over the scene's background, alpha) of each held-out view."""
    out = []
    for cam in bench.held_out:
        r = render(scene.detach(), [cam], background=bench.background, render_depth=False)
        rgb = (r.colors[0].clamp(0, 1).cpu().numpy() * 255 + 0.5).astype(np.uint8)
        out.append((rgb, r.alphas[0].cpu().numpy().reshape(rgb.shape[:2])))
    return out


def view_stats(views: list[tuple[np.ndarray, np.ndarray]]) -> list[measure.ViewStats]:
    return [measure.view_stats(rgb, alpha) for rgb, alpha in views]


def score(views: list[measure.ViewStats], stats: list[measure.TextureStats]) -> dict[str, Any]:
    """Per measure: each texture's distance, mean over the views."""
    per_view = [measure.distances(v, stats) for v in views]
    return {m: {t.name: float(np.mean([v[m][t.name] for v in per_view])) for t in stats} for m in MEASURES}


def projected(
    bench: BenchScene, texture: Path, height: int, config: TransferConfig, alphas: list[np.ndarray]
) -> list[tuple[np.ndarray, np.ndarray]]:
    """The calibration's views: the texture alone (``keep`` 0: none of the scene's light or colour, so the measure
    must find it) projected in screen space over the object as each held-out view sees it, ``height`` px tall at
    ``config``'s resolution, with the original's ``alphas``."""
    return [
        (
            orientation_preview(
                bench.scene,
                texture,
                cam,
                config.angle,
                size=max(cam.width, cam.height),
                pixel_scale=max(cam.width, cam.height) / config.resolution,  # the run's field of view
                texture_height=height,
                background=bench.background,
                keep=0.0,
            ),
            alpha,
        )
        for cam, alpha in zip(bench.held_out, alphas, strict=True)
    ]


def sketched(
    run: RunPlan, bench: BenchScene, texture: Path, alphas: list[np.ndarray]
) -> list[tuple[np.ndarray, np.ndarray]]:
    """A ``layout``-off run's preview of each held-out view (the engine's ``sketch`` of its plan with ``texture``),
    with the original's ``alphas``."""
    plan = replace(run, texture=run_texture(texture, run.config))
    return [(sketch(plan, cam, max(cam.width, cam.height)), a) for cam, a in zip(bench.held_out, alphas, strict=True)]


def content_ssim(views: Views, original: Views) -> float:
    """How much of the scene is still there: the product's *Scene Kept* (``object_ssim``, luminance SSIM over the
    original's object pixels) of each view to the original's render of it, mean over the views (1: the original;
    the structure measures ignore it); NaN when no view covers a window."""
    values = []
    for (rgb, _), (reference, alpha) in zip(views, original, strict=True):
        image, then = (torch.from_numpy(measure.to_float(x))[None] for x in (rgb, reference))
        values.append(object_ssim(image, then, torch.from_numpy(alpha > measure.MASK_ALPHA)[None]))
    covered = [v for v in values if v is not None]
    return float(np.mean(covered)) if covered else float("nan")


def colour_specks(views: Views, original: Views) -> float:
    """Colour noise: the share of the object's pixels whose chroma (R - Y, B - Y) lies further than
    ``SPECK_CHROMA`` from the median chroma of their ``SPECK_WINDOW`` px neighbourhood, mean over the views
    (the original's own specks, a sprinkle or a flower, are its row's value; no loss looks at a neighbourhood)."""
    luma = torch.tensor(measure.LUMA)
    values = []
    for (rgb, _), (_, alpha) in zip(views, original, strict=True):
        image = torch.from_numpy(measure.to_float(rgb))
        y = image @ luma
        chroma = torch.stack([image[..., 0] - y, image[..., 2] - y])[None]
        pad = SPECK_WINDOW // 2
        around = F.unfold(F.pad(chroma, (pad, pad, pad, pad), mode="replicate"), SPECK_WINDOW)
        median = around.view(2, SPECK_WINDOW**2, -1).median(1).values.view_as(chroma[0])
        far = (chroma[0] - median).norm(dim=0) > SPECK_CHROMA
        mask = torch.from_numpy(alpha > measure.MASK_ALPHA)
        if mask.any():
            values.append(float(far[mask].float().mean()))
    return float(np.mean(values)) if values else float("nan")


def accent_shift(views: Views, original: Views) -> float:
    """Are the scene's small, vivid features still their colour (a robot's eyes, sprinkles): the mean Lab (a, b)
    distance of each view to the original's render of it over the original's accent pixels (object pixels of chroma
    over ``ACCENT_CHROMA`` lying more than ``ACCENT_APART`` from the median (a, b) of their ``ACCENT_WINDOW`` px
    neighbourhood), pooled over the views; NaN where the scene shows none. Judged on the renders, apart from the
    engine's rule (which weighs splats, not pixels)."""
    shifts = []
    for (rgb, _), (reference, alpha) in zip(views, original, strict=True):
        lab_then = cv2.cvtColor(reference, cv2.COLOR_RGB2Lab)  # uint8: a and b offset by 128
        around = np.stack([cv2.medianBlur(lab_then[..., c], ACCENT_WINDOW) for c in (1, 2)], axis=-1)
        ab_then, ab = (cv2.cvtColor(measure.to_float(x), cv2.COLOR_RGB2Lab)[..., 1:] for x in (reference, rgb))
        apart = np.linalg.norm(lab_then[..., 1:].astype(np.float32) - around, axis=-1) * (255.0 / 256.0)
        accent = (
            (alpha > measure.MASK_ALPHA) & (np.linalg.norm(ab_then, axis=-1) > ACCENT_CHROMA) & (apart > ACCENT_APART)
        )
        shifts.extend(np.linalg.norm(ab[accent] - ab_then[accent], axis=-1))
    return float(np.mean(shifts)) if shifts else float("nan")


def blurred_ab(rgb: np.ndarray, sigma: float) -> np.ndarray:
    """Lab (a, b) (H, W, 2) of an RGB uint8 view, blurred by ``sigma`` px: its hue at the scale a patch counts."""
    return cv2.GaussianBlur(cv2.cvtColor(measure.to_float(rgb), cv2.COLOR_RGB2Lab)[..., 1:], (0, 0), sigma)


def hue_drift(views: Views, start: Views, original: Views) -> float:
    """Hue the optimisation painted of its own (the guitar's pink and green patches under woven straw): the mean Lab
    (a, b) distance of each held-out view to the same view of the run's start (the laid-out splats before any
    step), both blurred by ``HUE_DRIFT_BLUR``, over the original's object pixels, pooled over the views; 0 where
    the steps only lightened or darkened. Judged on renders no loss sees (the layout term holds the start's exact
    surface, not its splats); NaN without a start (the layout off)."""
    drifts = []
    for (rgb, _), (then, _), (_, alpha) in zip(views, start, original, strict=True):
        sigma = HUE_DRIFT_BLUR * max(alpha.shape)
        drifts.extend(
            np.linalg.norm(blurred_ab(rgb, sigma) - blurred_ab(then, sigma), axis=-1)[alpha > measure.MASK_ALPHA]
        )
    return float(np.mean(drifts)) if drifts else float("nan")


def own_hue(views: Views, start: Views, original: Views) -> float:
    """The part of ``hue_drift`` that is no drift back toward the capture (which the layout term allows for free): the
    mean Lab (a, b) distance of each held-out view's blurred hue from the segment between its start's and the
    original's at that pixel, over the original's object pixels; 0 for a result anywhere between the two."""
    own = []
    for (rgb, _), (then, _), (first, alpha) in zip(views, start, original, strict=True):
        sigma = HUE_DRIFT_BLUR * max(alpha.shape)
        point, a, b = (blurred_ab(x, sigma)[alpha > measure.MASK_ALPHA] for x in (rgb, then, first))
        step = b - a
        along = ((point - a) * step).sum(-1) / np.maximum((step * step).sum(-1), np.finfo(np.float32).tiny)
        own.extend(np.linalg.norm(point - (a + np.clip(along, 0.0, 1.0)[:, None] * step), axis=-1))
    return float(np.mean(own)) if own else float("nan")


def part_hues(views: Views, original: Views) -> float:
    """Do the parts keep their hues apart (a donut's pink icing on its beige dough, a dark stand under a light
    guitar): each view's and the original's Lab (a, b) over the object's pixels, averaged to the object's scale
    (``OBJECT_BLUR``, within the object only), less their mean over it, compared as SSIM compares contrast and
    structure, ``(2 d.d' + C) / (|d|^2 + |d'|^2 + C)`` summed over the pixels of all views (``C``: ``HUE_FLOOR``
    squared a pixel). 1: every part's hue relative to the others kept (a tint over the whole object costs nothing:
    the texture's colour is what a run is for); 0: one hue for all; below 0: hues turned against the scene's."""
    dot = energy = floor = 0.0
    for (rgb, _), (reference, alpha) in zip(views, original, strict=True):
        mask = (alpha > measure.MASK_ALPHA).astype(np.float32)
        if not mask.any():
            continue
        sigma = OBJECT_BLUR * float(mask.sum()) ** 0.5
        weight = cv2.GaussianBlur(mask, (0, 0), sigma)
        inside = mask > 0
        hues = []
        for image in (rgb, reference):
            ab = cv2.cvtColor(measure.to_float(image), cv2.COLOR_RGB2Lab)[..., 1:] * mask[..., None]
            blurred = cv2.GaussianBlur(ab, (0, 0), sigma) / np.maximum(weight, 1e-6)[..., None]
            hues.append(blurred[inside] - blurred[inside].mean(axis=0))
        dot += float((hues[0] * hues[1]).sum())
        energy += float((hues[0] ** 2).sum() + (hues[1] ** 2).sum())
        floor += HUE_FLOOR**2 * float(inside.sum())
    return (2.0 * dot + floor) / (energy + floor) if floor else float("nan")


def scene_side(views: Views, original: Views) -> dict[str, float]:
    """The row's measures of the scene's side: ``content_ssim``, ``colour_specks``, ``accent_shift`` and
    ``part_hues``."""
    return {
        "content_ssim": content_ssim(views, original),
        "colour_specks": colour_specks(views, original),
        "accent_shift": accent_shift(views, original),
        "part_hues": part_hues(views, original),
    }


def from_preview(views: list[measure.ViewStats], preview: list[measure.ViewStats]) -> dict[str, float]:
    """Per measure: the image-to-image distance of each held-out view to the preview of that view, mean over
    the views (views with no window in common left out)."""
    pairs = [measure.pair_distance(a, b) for a, b in zip(views, preview, strict=True)]
    out = {}
    for m in MEASURES:
        values = [p[m] for p in pairs if p["windows"]]
        out[m] = float(np.mean(values)) if values else float("nan")
    return out


def run_config(preset_name: str, args: argparse.Namespace, bench: BenchScene, seed: int) -> TransferConfig:
    overrides = {"weights_path": str(SHARED / "weights"), "background": bench.background, "seed": seed}
    return preset(preset_name, **{**overrides, **args.overrides})


def reusable(saved: dict[str, Any], settings: dict[str, Any], older: bool) -> tuple[bool, list[str]]:
    """Whether a result saved with ``saved`` settings is the one ``settings`` would make: the same value for
    every setting both have; settings missing from ``saved`` (added since) only when ``older``. Also returns
    the names of those missing settings."""
    differ = sorted(k for k in saved.keys() & settings.keys() if saved[k] != settings[k])
    missing = sorted(settings.keys() - saved.keys())
    if differ:
        print(f"    saved settings differ: {', '.join(f'{k}={saved[k]!r}' for k in differ)}", flush=True)
    return not differ and (older or not missing), missing


def row(scene: str, texture: str, variant: str, dist: dict[str, Any], seconds: float | None = None) -> dict:
    return {
        "scene": scene,
        "texture": texture,
        "variant": variant,
        **{f"{m}_rank": measure.rank_of(dist[m], texture) for m in MEASURES},
        **{f"{m}_margin": measure.margin_of(dist[m], texture, TOP) for m in MEASURES},
        "seconds": seconds,
        "distances": dist,
    }


# ---------------------------------------------------------------------------------------------------
# Contact sheet
# ---------------------------------------------------------------------------------------------------
def tile(image: np.ndarray, label: str = "", size: int = TILE) -> np.ndarray:
    """RGB uint8 image fitted into a ``size`` square (grey margins), with a label."""
    image = np.asarray(image)
    if image.dtype != np.uint8:
        image = (np.clip(image, 0, 1) * 255 + 0.5).astype(np.uint8)
    scale = size / max(image.shape[:2])
    small = cv2.resize(
        image, (round(image.shape[1] * scale), round(image.shape[0] * scale)), interpolation=cv2.INTER_AREA
    )
    out = np.full((size, size, 3), 96, np.uint8)
    y, x = (size - small.shape[0]) // 2, (size - small.shape[1]) // 2
    out[y : y + small.shape[0], x : x + small.shape[1]] = small
    if label:
        cv2.rectangle(out, (0, size - 16), (size, size), (0, 0, 0), -1)
        cv2.putText(out, label, (3, size - 4), cv2.FONT_HERSHEY_SIMPLEX, 0.36, (255, 255, 255), 1, cv2.LINE_AA)
    return out


def write_sheet(path: Path, sheet: dict[str, list[np.ndarray]]) -> None:
    width = max(len(r) for r in sheet.values())
    rows = [np.hstack(r + [np.full((TILE, TILE, 3), 64, np.uint8)] * (width - len(r))) for r in sheet.values()]
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), cv2.cvtColor(np.vstack(rows), cv2.COLOR_RGB2BGR))


def write_pictures(folder: Path, name: str, views: Views) -> None:
    """Each held-out view as ``<folder>/<name>-v<k>.png`` (bench/quality_figure.py draws from them)."""
    folder.mkdir(parents=True, exist_ok=True)
    for k, (rgb, _) in enumerate(views):
        cv2.imwrite(str(folder / f"{name}-v{k}.png"), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))


def output_name(args: argparse.Namespace) -> str:
    """The JSON, contact sheet and picture folder's name: the tag, with the size when not the default."""
    return args.tag if args.size == HELD_OUT_SIZE else f"{args.tag}-{args.size}px"


def ranks_label(r: dict, name: str) -> str:
    return f"{name} G{r['gram_rank']} B{r['gabor_rank']}"


# ---------------------------------------------------------------------------------------------------
# The benchmark
# ---------------------------------------------------------------------------------------------------
@dataclass
class SceneRun:
    """What the rows of every texture on one bench scene share: the scene, its original's renders and scores, and
    each preset's run plan with the preview its results are compared with."""

    name: str
    args: argparse.Namespace
    stats: list[measure.TextureStats]
    bench: BenchScene
    original_views: Views
    original_stats: list[measure.ViewStats]
    original: dict[str, Any]
    """The original's structure distances to every texture."""
    starts: dict[str, RunPlan]
    references: dict[str, str]
    """Per preset, the preview variant its results are compared with: its layout start, else its sketch."""
    surfaces: dict[str, ViewSet]

    @property
    def alphas(self) -> list[np.ndarray]:
        return [alpha for _, alpha in self.original_views]

    @property
    def folder(self) -> Path:
        """Where the results are saved, whatever size measures them."""
        return OUT / self.args.tag / self.name

    @property
    def pictures(self) -> Path:
        return OUT / output_name(self.args) / self.name


def scene_run(name: str, args: argparse.Namespace, stats: list[measure.TextureStats]) -> SceneRun:
    """The bench scene ``name`` loaded, its original scored and each preset's run plan prepared."""
    bench = load_bench_scene(name, args.size)
    start = time.perf_counter()
    original_views = held_out_renders(bench.scene, bench)
    original_stats = view_stats(original_views)
    original = score(original_stats, stats)
    print(f"[{name}] original scored in {time.perf_counter() - start:.1f} s", flush=True)
    first_texture = texture_path(args.textures[0])  # the plans differ only in the texture, swapped in per texture
    starts = {p: run_start(bench, run_config(p, args, bench, args.seeds[0]), first_texture) for p in args.presets}
    print(f"[{name}] run starts prepared in {time.perf_counter() - start:.1f} s", flush=True)
    references = {
        p: (f"{p}-" if len(args.presets) > 1 else "") + ("layout-start" if r.config.layout else "sketch")
        for p, r in starts.items()
    }
    surfaces = {p: surface_views(bench, r.config.backend) for p, r in starts.items() if r.config.layout}
    return SceneRun(name, args, stats, bench, original_views, original_stats, original, starts, references, surfaces)


def measured_row(
    run: SceneRun,
    texture: str,
    variant: str,
    views: Views,
    stats: list[measure.ViewStats],
    seconds: float | None = None,
) -> dict:
    """A row for ``views`` of ``texture`` (``stats``: their window statistics): structure ranks and the scene side
    against the original."""
    p = row(run.name, texture, variant, score(stats, run.stats), seconds)
    p.update(scene_side(views, run.original_views))
    return p


def calibration_rows(
    run: SceneRun,
    texture: str,
    tiles: list[np.ndarray],
    previews: dict[str, list[measure.ViewStats]],
    started: dict[str, Views],
) -> list[dict]:
    """The texture shown to the measure without a transfer: projected in screen space at each height, and for each
    preset its preview (the layout start, the run's target and the texture alone on the exact surface, or the
    sketch); fills ``previews`` (variant -> view statistics), ``started`` (the layout starts' views) and ``tiles``."""
    rows = []
    path = texture_path(texture)
    base_config = preset(run.args.presets[0], **run.args.overrides)
    for height in run.args.projected_heights:
        variant = f"projected-{height}"
        views = projected(run.bench, path, height, base_config, run.alphas)
        previews[variant] = view_stats(views)
        rows.append(measured_row(run, texture, variant, views, previews[variant]))
        tiles.append(tile(views[0][0], ranks_label(rows[-1], f"proj{height}")))
    for preset_name, plan in run.starts.items():
        t0 = time.perf_counter()
        variant = run.references[preset_name]
        if not plan.config.layout:
            views = sketched(plan, run.bench, path, run.alphas)
            previews[variant] = view_stats(views)
            rows.append(measured_row(run, texture, variant, views, previews[variant], time.perf_counter() - t0))
            tiles.append(tile(views[0][0], ranks_label(rows[-1], "sketch")))
            continue
        views = held_out_renders(layout_start(plan, path), run.bench)
        started[variant] = views
        previews[variant] = view_stats(views)
        rows.append(measured_row(run, texture, variant, views, previews[variant], time.perf_counter() - t0))
        tiles.append(tile(views[0][0], ranks_label(rows[-1], variant.removesuffix("-start"))))
        write_pictures(run.pictures, f"{texture}-{variant}", views)
        for kind, shaded in (("target", True), ("surface", False)):
            views = layout_surface(plan, run.bench, path, shaded, run.surfaces[preset_name])
            kind_variant = variant.removesuffix("-start") + f"-{kind}"
            rows.append(measured_row(run, texture, kind_variant, views, view_stats(views)))
            tiles.append(tile(views[0][0], ranks_label(rows[-1], kind)))
    return rows


def saved_or_transferred(
    run: SceneRun, texture: str, config: TransferConfig, variant: str
) -> tuple[GaussianScene, float, Any, bool, list[str]]:
    """The result of ``texture`` under ``config``: read back when ``--reuse`` finds one saved with the same settings,
    else transferred and saved. Returns it, its transfer's seconds, its feature weights, whether it was reused and
    the settings its saved copy predates."""
    saved = run.folder / f"{texture}-{variant}.ply"
    settings = json.dumps(config.to_dict(), sort_keys=True, default=str)
    if run.args.reuse and saved.is_file() and saved.with_suffix(".json").is_file():
        kept = json.loads(saved.with_suffix(".json").read_text())
        ok, missing = reusable(json.loads(kept["config"]), json.loads(settings), run.args.reuse_older)
        if ok:
            note = f" (saved before: {', '.join(missing)})" if missing else ""
            print(f"[{run.name}] {texture} {variant}: reusing {saved}{note}", flush=True)
            return read_scene(saved), kept["seconds"], kept["features"], True, missing
        print(f"[{run.name}] {texture} {variant}: {saved} has other settings, transferring", flush=True)
    t0 = time.perf_counter()
    result = transfer(run.bench.scene, texture_path(texture), run.bench.transfer_views, config)
    seconds = time.perf_counter() - t0
    features = result.report.get("weights")
    run.folder.mkdir(parents=True, exist_ok=True)
    write_ply(saved, result.scene)
    kept = {"config": settings, "seconds": seconds, "features": features}
    kept.update({key: result.report.get(key) for key in ("stage_seconds", "stylise", "metrics")})
    saved.with_suffix(".json").write_text(json.dumps(kept, default=str))
    return result.scene, seconds, features, False, []


def result_row(
    run: SceneRun,
    texture: str,
    preset_name: str,
    seed: int,
    previews: dict[str, list[measure.ViewStats]],
    started: dict[str, Views],
    original_row: dict,
    tiles: list[np.ndarray],
) -> dict:
    """The row of one transfer of ``texture`` (``preset_name``, ``seed``): structure ranks, the scene side and the
    distance from its preview beside the original's; adds its held-out views to ``tiles``."""
    variant = f"{preset_name}-s{seed}"
    reference = run.references[preset_name]
    config = run_config(preset_name, run.args, run.bench, seed)
    result_scene, seconds, features, reused, missing = saved_or_transferred(run, texture, config, variant)
    views = held_out_renders(result_scene, run.bench)
    result_stats = view_stats(views)
    t = row(run.name, texture, variant, score(result_stats, run.stats), seconds)
    t["features"] = features
    t["splats"] = len(result_scene)  # what the saved file holds: the split's cost beside its seconds
    t.update(scene_side(views, run.original_views))
    start = started.get(reference)
    for key, hue in (("hue_drift", hue_drift), ("own_hue", own_hue)):
        t[key] = float("nan") if start is None else hue(views, start, run.original_views)
    t.update(preview_fields(from_preview(result_stats, previews[reference]), reference, run.starts[preset_name]))
    scale = (
        {m: original_row[f"preview_{m}"] for m in MEASURES}
        if reference == run.references[run.args.presets[0]]
        else from_preview(run.original_stats, previews[reference])
    )
    t.update({f"original_preview_{m}": v for m, v in scale.items()})
    t["reused"] = reused
    if missing:
        t["reused_settings_missing"] = missing
    print(
        f"[{run.name}] {texture} {variant}: {seconds:.0f} s, {t['splats']:,} splats, "
        f"ranks gram {t['gram_rank']} gabor {t['gabor_rank']}, from {reference}: "
        f"gram {t['preview_gram']:.3f} gabor {t['preview_gabor']:.3f} "
        f"(original {t['original_preview_gram']:.3f} / {t['original_preview_gabor']:.3f})",
        flush=True,
    )
    for k, (rgb, _) in enumerate(views[:SHEET_VIEWS]):
        tiles.append(tile(rgb, ranks_label(t, f"{variant} v{k}") if k == 0 else f"{variant} v{k}"))
    write_pictures(run.pictures, f"{texture}-{variant}", views)
    return t


def run_scene(name: str, args: argparse.Namespace, stats: list[measure.TextureStats]) -> tuple[list[dict], dict]:
    """Every row of one scene (the calibration, then each texture's transfers unless ``--only-measure``), its
    contact sheet written; returns the rows and the scene's entry of the report."""
    run = scene_run(name, args, stats)
    write_pictures(run.pictures, "original", run.original_views)
    rows: list[dict] = []
    sheet: dict[str, list[np.ndarray]] = {}
    first = run.references[args.presets[0]]
    for texture in args.textures:
        image = cv2.cvtColor(cv2.imread(str(texture_path(texture))), cv2.COLOR_BGR2RGB)
        tiles = sheet[texture] = [tile(image, texture)]
        previews: dict[str, list[measure.ViewStats]] = {}
        started: dict[str, Views] = {}
        rows += calibration_rows(run, texture, tiles, previews, started)
        r = row(name, texture, "original", run.original)
        r.update(scene_side(run.original_views, run.original_views))  # content 1: the original is the scene
        r.update(preview_fields(from_preview(run.original_stats, previews[first]), first, run.starts[args.presets[0]]))
        rows.append(r)
        tiles.append(tile(run.original_views[0][0], ranks_label(r, "original")))
        if args.only_measure:
            continue
        for preset_name in args.presets:
            for seed in args.seeds:
                rows.append(result_row(run, texture, preset_name, seed, previews, started, r, tiles))
    write_sheet(OUT / f"{output_name(args)}-{name}.png", sheet)
    return rows, {
        "held_out": [c.name for c in run.bench.held_out],
        "background": run.bench.background,
        "preview": {
            p: {
                "reference": run.references[p],
                "kind": "layout_start" if r.config.layout else "orientation_preview",
                "texture_height": r.config.texture_height,
            }
            for p, r in run.starts.items()
        },
    }


def preview_fields(distance: dict[str, float], reference: str, run: RunPlan) -> dict[str, Any]:
    return {
        "preview_gram": distance["gram"],
        "preview_gabor": distance["gabor"],
        "preview_reference": reference,
        "preview_kind": "layout_start" if run.config.layout else "orientation_preview",
    }


def summarise(rows: list[dict]) -> dict[str, dict[str, dict]]:
    """Per scene and variant: how many textures rank top 1 / top TOP under each measure and both, the means of
    ``SUMMED`` and the least content SSIM over the textures."""
    out: dict[str, dict[str, dict]] = {}
    for r in rows:
        s = out.setdefault(r["scene"], {}).setdefault(
            r["variant"],
            {"n": 0, "top1_gram": 0, "top1_gabor": 0, f"top{TOP}_gram": 0, f"top{TOP}_gabor": 0, f"top{TOP}_both": 0},
        )
        s["n"] += 1
        for m in MEASURES:
            s[f"top1_{m}"] += r[f"{m}_rank"] == 1
            s[f"top{TOP}_{m}"] += r[f"{m}_rank"] <= TOP
        s[f"top{TOP}_both"] += all(r[f"{m}_rank"] <= TOP for m in MEASURES)
        edge = decisive_margin(r)
        if abs(edge) < abs(s.get("nearest_flip", math.inf)):
            s["nearest_flip"], s["nearest_flip_texture"] = edge, r["texture"]
        for key in SUMMED:
            if key in r:
                s.setdefault(f"{key}_values", []).append(r[key])
    for variants in out.values():
        for s in variants.values():
            for key in [k for k in s if k.endswith("_values")]:
                values = s.pop(key)
                s[f"mean_{key.removesuffix('_values')}"] = float(np.nanmean(values))
                if key == "content_ssim_values":  # the texture that keeps the least of the scene, hidden by the mean
                    s["least_content_ssim"] = float(np.nanmin(values))
    return out


def decisive_margin(r: dict) -> float:
    """The margin (``measure.margin_of``) that decides whether row ``r``'s texture is found under both measures:
    the smaller of the two; >= 0 when found, and its size the share the distances must move to change that."""
    return min(r.get(f"{m}_margin", math.nan) for m in MEASURES)


def target_met(summary: dict[str, dict[str, dict]]) -> dict[str, bool]:
    """Per "scene/variant" transfer: whether at least ``NEEDED`` textures rank top ``TOP`` under both measures."""
    return {
        f"{scene}/{variant}": s[f"top{TOP}_both"] >= NEEDED
        for scene, variants in summary.items()
        for variant, s in variants.items()
        if is_transfer(variant)
    }


SAME_SETTINGS = ("presets", "seeds", "textures", "projected_heights", "size", "only_measure")
"""What two runs under one tag share for their scenes to stand in one report (with the overrides and the measure)."""


def settings_of(args: argparse.Namespace) -> dict:
    """The settings a report's scenes were measured with, as its JSON holds them."""
    settings = {key: getattr(args, key) for key in SAME_SETTINGS}
    return json.loads(json.dumps({**settings, "overrides": args.overrides, "measure": measure.PARAMS}, default=str))


def earlier_scenes(path: Path, args: argparse.Namespace) -> dict:
    """The report at ``path`` cut to the scenes this run does not measure (empty when there is none), so a tag can be
    filled one scene at a time; SystemExit naming the file when those scenes ran with other settings."""
    if not path.is_file():
        return {}
    earlier = json.loads(path.read_text())
    others = [scene for scene in earlier.get("scenes", {}) if scene not in args.scenes]
    if not others:
        return {}
    then = {key: earlier["args"].get(key) for key in SAME_SETTINGS}
    then.update({key: earlier.get(key) for key in ("overrides", "measure")})
    differ = [key for key, value in settings_of(args).items() if then[key] != value]
    if differ:
        raise SystemExit(
            f"{path} holds {', '.join(others)} measured with other {', '.join(differ)}: use another --tag, or remove "
            "the file to start the tag again"
        )
    return {
        "scenes": {scene: earlier["scenes"][scene] for scene in others},
        "rows": [r for r in earlier["rows"] if r["scene"] in others],
    }


def is_transfer(variant: str) -> bool:
    calibration = variant.startswith("projected") or variant.endswith(
        ("sketch", "layout-start", "layout-target", "layout-surface")
    )
    return variant != "original" and not calibration


def print_table(rows: list[dict], summary: dict) -> None:
    print(
        f"\n{'scene':6} {'texture':17} {'variant':18} {'gram':>4} {'gabor':>5} {'edge':>6} {'seconds':>8} "
        f"{'scene SSIM':>10} {'specks':>6} {'accents':>7} {'hues':>5}   from preview gram / gabor (original's)"
    )
    for r in rows:
        sec = "" if r["seconds"] is None else f"{r['seconds']:.0f}"
        preview = ""
        if "preview_gram" in r:
            preview = f"{r['preview_gram']:.3f} / {r['preview_gabor']:.3f}"
            if "original_preview_gram" in r:
                preview += f" ({r['original_preview_gram']:.3f} / {r['original_preview_gabor']:.3f})"
            preview += f" vs {r['preview_reference']}"
        print(
            f"{r['scene']:6} {r['texture']:17} {r['variant']:18} {r['gram_rank']:>4} {r['gabor_rank']:>5} "
            f"{decisive_margin(r):>+6.1%} {sec:>8} "
            f"{r['content_ssim']:>10.3f} {r['colour_specks']:>6.3f} {r['accent_shift']:>7.1f} "
            f"{r.get('part_hues', float('nan')):>5.2f}   {preview}"
        )
    print(
        f"\nper scene and variant: textures in the top {TOP} under Gram / Gabor / both (top 1: Gram / Gabor), "
        "scene SSIM (how much of the original scene shows; mean, least), colour specks (share of pixels; mean), "
        "accents (Lab a, b shift of the original's small, vivid features; mean), hues (the parts' hues kept apart, "
        "1 = as the original; mean), drift (Lab a, b the steps moved the hues from the start; mean), own (the drift "
        "off the way back to the original's hue; mean)"
    )
    for scene, variants in summary.items():
        for variant, s in variants.items():
            tail = f"   splats {s['mean_splats']:,.0f}" if "mean_splats" in s else ""
            if "nearest_flip" in s:
                tail += f"   nearest flip {s['nearest_flip_texture']} {s['nearest_flip']:+.1%}"
            if "mean_original_preview_gram" in s:
                tail += (
                    f"   from preview {s['mean_preview_gram']:.3f} / {s['mean_preview_gabor']:.3f} "
                    f"(original {s['mean_original_preview_gram']:.3f} / {s['mean_original_preview_gabor']:.3f})"
                )
            print(
                f"  {scene:6} {variant:18} {s[f'top{TOP}_gram']}/{s['n']} {s[f'top{TOP}_gabor']}/{s['n']} "
                f"{s[f'top{TOP}_both']}/{s['n']}   (top 1: {s['top1_gram']} / {s['top1_gabor']})   "
                f"scene SSIM {s['mean_content_ssim']:.3f}, {s['least_content_ssim']:.3f}   "
                f"specks {s['mean_colour_specks']:.3f}   accents {s['mean_accent_shift']:.1f}   "
                f"hues {s.get('mean_part_hues', float('nan')):.2f}   "
                f"drift {s.get('mean_hue_drift', float('nan')):.2f}   "
                f"own {s.get('mean_own_hue', float('nan')):.2f}{tail}"
            )
    met = target_met(summary)
    for key, ok in met.items():
        print(f"target (top {TOP} under both measures for >= {NEEDED} textures) {key}: {'MET' if ok else 'not met'}")
    if not met:
        print("target: no transfer ran (--only-measure)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="+", default=["donut", "fern"], choices=SCENES)
    parser.add_argument("--textures", nargs="+", default=list(STRUCTURED), metavar="NAME")
    parser.add_argument("--presets", "--preset", nargs="+", default=["fast"], metavar="PRESET")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help="TransferConfig override")
    parser.add_argument("--seeds", nargs="+", type=int, default=[0])
    parser.add_argument("--tag", help="output name (default: the presets, then 'calibration' with --only-measure)")
    parser.add_argument(
        "--only-measure", action="store_true", help="calibration only: projected and original, no transfer"
    )
    parser.add_argument("--projected-heights", nargs="+", type=int, default=[64, 128], metavar="PX")
    parser.add_argument(
        "--reuse", action="store_true", help="measure results saved by an earlier run with the same settings again"
    )
    parser.add_argument(
        "--reuse-older",
        action="store_true",
        help="with --reuse: also results saved before some of today's settings existed (listed in their rows)",
    )
    parser.add_argument(
        "--size",
        type=int,
        default=HELD_OUT_SIZE,
        metavar="PX",
        help=f"held-out views' longest side (default {HELD_OUT_SIZE}); other sizes write <tag>-<size>px outputs",
    )
    parser.add_argument("--threads", type=int, default=0, help="torch CPU threads for the measure (0: torch's default)")
    args = parser.parse_args()
    args.overrides = parse_overrides(args.set)
    for p in args.presets:
        preset(p, **args.overrides)  # fail early on an unknown preset or a value out of range
    args.tag = args.tag or ("calibration" if args.only_measure else "-".join(args.presets))
    if args.threads:
        torch.set_num_threads(args.threads)

    out = output_name(args)
    kept = earlier_scenes(OUT / f"{out}.json", args)
    start = time.perf_counter()
    stats = [measure.cached_texture_stats(p) for p in sorted(TEXTURES.iterdir()) if p.is_file()]
    print(f"texture statistics ({len(stats)} textures) in {time.perf_counter() - start:.1f} s", flush=True)
    rows, scenes = [], {}
    for name in args.scenes:
        scene_rows, scenes[name] = run_scene(name, args, stats)
        rows += scene_rows
    summary = summarise(rows)
    print_table(rows, summary)
    if kept:
        print(f"kept from {OUT / (out + '.json')}: {', '.join(kept['scenes'])} (an earlier run under this tag)")
        rows, scenes = kept["rows"] + rows, {**kept["scenes"], **scenes}
        summary = summarise(rows)
    report = {
        "tag": args.tag,
        "args": {k: v for k, v in vars(args).items() if k != "overrides"},
        "kept_scenes": list(kept.get("scenes", {})),  # from an earlier run under this tag; "args" are this run's
        "overrides": args.overrides,
        "measure": measure.PARAMS,
        "scenes": scenes,
        "rows": rows,
        "summary": summary,
        "target": {"top": TOP, "needed": NEEDED, "met": target_met(summary)},
        "load_average": os.getloadavg(),
    }
    OUT.mkdir(parents=True, exist_ok=True)
    atomic_write(OUT / f"{out}.json", json.dumps(report, indent=1, default=str))
    print(f"wrote {OUT / (out + '.json')} and contact sheets {OUT / out}-<scene>.png")


if __name__ == "__main__":
    main()
