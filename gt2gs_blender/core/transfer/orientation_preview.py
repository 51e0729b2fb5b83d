"""A quick picture of how the texture will lie on the scene at a chosen orientation angle.

``preview`` is the one entry point (the CLI, the API and the worker's preview job use it; the run's preview
agreement calls ``show`` on its own plan): with ``layout`` on it shows the texture laid out exactly as the run
lays it; otherwise ``orientation_preview``, the screen-space sketch below, at the texture size the run will use.

The first view is rendered once; over the pixels the scene covers, the texture is laid out rotated
by the angle (counter-clockwise on screen, the texture bank's convention) and scaled per depth
group as the texture bank scales it (nearest group largest, by the view's own depth ratio unless
one is given), then shaded by the render's
luminance so the shape stays readable. No optimisation runs: it takes a fraction of a second and
lets an artist choose the angle before starting a transfer.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
import torch

from ..cameras.camera import Camera
from ..features.specs import RENDER_SCALE
from ..render import render
from ..scene.gaussians import GaussianScene
from .accents import ColourShare
from .config import MAX_DEPTH_RATIO, TransferConfig
from .detail import add_detail
from .layout import lay_out, layout_materials, layout_shading, scene_colour_mix
from .plan import RunPlan, plan_run
from .region import assemble
from .shade import kept_scene, shading, under_scene
from .texture import load_texture
from .texture_bank import bank_scales, depth_groups, group_depth_ratio, screen_rotation
from .tone import luma

MIN_ALPHA = 0.05
"""Pixels with less coverage than this show the background only."""


def texture_layer(texture: np.ndarray, angle_deg: float, scale: float, width: int, height: int) -> np.ndarray:
    """The texture tiled over a ``width`` x ``height`` image, ``scale`` image pixels per texture pixel,
    rotated ``angle_deg`` counter-clockwise on screen about the image centre."""
    linear = scale * screen_rotation(angle_deg)
    tex_centre = np.array([(texture.shape[1] - 1) / 2.0, (texture.shape[0] - 1) / 2.0])
    img_centre = np.array([(width - 1) / 2.0, (height - 1) / 2.0])
    matrix = np.hstack([linear, (img_centre - linear @ tex_centre)[:, None]])
    return cv2.warpAffine(texture, matrix, (width, height), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)


@torch.no_grad()
def orientation_preview(
    scene: GaussianScene,
    texture: np.ndarray | str | os.PathLike,
    camera: Camera,
    angle_deg: float,
    *,
    size: int = 256,
    pixel_scale: float = 1.0,
    texture_height: int = 256,
    n_groups: int = 4,
    depth_ratio: float = 0.0,
    background: tuple[float, float, float] = (1.0, 1.0, 1.0),
    backend: str = "auto",
    keep: float = 1.0,
    colour: float | ColourShare = 0.0,
) -> np.ndarray:
    """(H, W, 3) uint8 preview of ``camera`` resized to longest side ``size``, the texture over the scene as
    the layout lays it (:func:`under_scene`): shaded by the scene's luminance to the power ``keep`` (the run's
    ``keep_scene``), with ``colour`` of the scene's own colour mixed in (its ``scene_colour`` and accents:
    :func:`scene_colour_mix`).

    ``texture_height`` is the transfer's setting and ``pixel_scale`` ``camera``'s focal length over the transfer's
    views': the texture appears as large on screen as the transfer's texture bank makes it (its nearest scale spans
    ``texture_height / RENDER_SCALE`` pixels of the transfer's views), so the preview matches the run.
    ``depth_ratio`` is the run's setting too (0: measured, here on this view alone).
    """
    image = load_texture(texture) if not isinstance(texture, np.ndarray) else np.asarray(texture[..., :3], np.float32)
    cam = camera.scaled(size / max(camera.width, camera.height))
    out = render(scene.detach(), [cam], backend=backend)
    premultiplied, alpha, depth = out.colors[0].cpu().numpy(), out.alphas[0], out.depths[0]
    groups = depth_groups(depth, alpha, n_groups, min_alpha=MIN_ALPHA).cpu().numpy()
    alpha = alpha.cpu().numpy()
    covered = groups >= 0

    seen = torch.from_numpy(premultiplied / np.maximum(alpha, MIN_ALPHA)[..., None]).clamp(0.0, 1.0)
    luminance = luma(seen)
    kept = kept_scene(
        shading(luminance, luminance[torch.from_numpy(covered)], keep).reshape(-1), seen.reshape(-1, 3), colour
    )

    nearest_px = texture_height / RENDER_SCALE * pixel_scale * size / max(camera.width, camera.height) / image.shape[0]
    laid = np.zeros((cam.height, cam.width, 3), np.float32)
    if depth_ratio <= 0.0:
        depth_ratio = min(group_depth_ratio(depth, out.alphas[0], n_groups, min_alpha=MIN_ALPHA), MAX_DEPTH_RATIO)
    for k, factor in enumerate(bank_scales(n_groups, (1.0, depth_ratio))):
        mask = groups == k
        if mask.any():
            laid[mask] = texture_layer(image, angle_deg, nearest_px * factor, cam.width, cam.height)[mask]
    cover = np.where(covered, alpha, 0.0)[..., None]
    laid = under_scene(torch.from_numpy(laid).reshape(-1, 3), kept).reshape(laid.shape).numpy()
    result = laid * cover + np.asarray(background, np.float32) * (1.0 - cover)
    return (np.clip(result, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)


@dataclass(frozen=True)
class Preview:
    """What the orientation preview shows an artist before a run."""

    image: np.ndarray
    """(H, W, 3) uint8: the first view."""
    splats: int
    """How many splats the run starts its optimisation from (after the layout's detail split): what the saved
    file will hold, give or take densification."""
    views: int
    """How many views the run optimises over."""
    size: tuple[int, int]
    """The run's views' width and height: larger than *Resolution* for a dense capture (``working_resolution``)."""


@torch.no_grad()
def laid_out_start(plan: RunPlan) -> GaussianScene:
    """The scene as a run of ``plan`` (``layout`` on) starts its optimisation: the texture laid out on the
    restyled splats the views see, split to the texture's detail (the run splits before or after, into the
    same children); hidden splats keep their colours, as the run keeps them."""
    config, frame, texture = plan.config, plan.frame, plan.texture
    work, region = plan.work, plan.region
    mix = scene_colour_mix(work, region, config)
    bright, parts = layout_materials(work, region, config)
    shade = layout_shading(work, region, frame, config, texture, mix, bright, parts)
    laid = lay_out(work, region, plan.content, texture, frame, config, shade)
    if config.split_size > 0:
        laid, region = add_detail(laid, laid.base_colors, region, plan.content, texture, frame, config, shade)
    return assemble(laid, region, plan.start, plan.selected, plan.hidden, changed=True)


@torch.no_grad()
def show(plan: RunPlan, *, size: int = 256) -> Preview:
    """The first view of ``plan`` at longest side ``size``: with ``layout`` on, the scene laid out exactly as
    the run starts (split to its detail, without the optimisation's changes); else the screen-space sketch
    at the texture size and depth ratio the run uses."""
    config, first = plan.config, plan.cameras[0]
    views = (len(plan.cameras), (first.width, first.height))
    if config.layout:
        laid = laid_out_start(plan)
        return Preview(first_view(plan, laid, size), len(laid), *views)
    return Preview(sketch(plan, first, size), len(plan.original), *views)


@torch.no_grad()
def first_view(plan: RunPlan, scene: GaussianScene, size: int) -> np.ndarray:
    """(H, W, 3) uint8: ``scene`` from ``plan``'s first view at longest side ``size``, over the run's background."""
    first = plan.cameras[0]
    cam = first.scaled(size / max(first.width, first.height))
    out = render(scene, [cam], background=plan.background, backend=plan.config.backend)
    return (out.colors[0].clamp(0.0, 1.0).cpu().numpy() * 255.0 + 0.5).astype(np.uint8)


def sketch(plan: RunPlan, camera: Camera, size: int = 256) -> np.ndarray:
    """(H, W, 3) uint8: the screen-space sketch of a run of ``plan`` with ``layout`` off, seen from ``camera`` at
    longest side ``size``: the run's texture, size, depth groups and kept scene (``orientation_preview``)."""
    config = plan.config
    return orientation_preview(
        plan.original,
        plan.texture,
        camera,
        config.angle,
        size=size,
        pixel_scale=camera.fx / plan.cameras[0].fx,
        texture_height=config.texture_height,
        n_groups=config.n_scales if config.depth_groups else 1,
        depth_ratio=config.depth_ratio,
        background=config.background,
        backend=config.backend,
        keep=config.keep_scene,
        colour=scene_colour_mix(plan.work, plan.region, config),
    )


@torch.no_grad()
def preview(
    scene: GaussianScene,
    texture: np.ndarray | str | os.PathLike,
    cameras: Sequence[Camera] | int | None,
    config: TransferConfig,
    *,
    size: int = 256,
    region: torch.Tensor | np.ndarray | None = None,
) -> Preview:
    """The first of ``cameras`` (or of the automatic views a count or None asks for): what a run with
    ``config`` will lay on ``scene`` (on its ``region`` only, when given), from the run's own plan."""
    return show(plan_run(scene, texture, cameras, config, region, preview=True), size=size)
