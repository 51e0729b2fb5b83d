"""The texture laid on the object before the optimisation: the structure (planks, bricks, cells) a
feature loss with a receptive field of ~24 px cannot build from the original colours at CPU budgets.

The layout is a box (tri-planar) projection in the world, the 3D form of GT²'s geometry-aware
scale and orientation: one texture size in the world whatever the view's depth, and one layout
every view agrees on.
- Frame: ``up`` is the views' mean up direction (an orbit's world up, a capture's camera up);
  ``right`` the first view's right made orthogonal to it; ``depth`` completes the frame. A surface
  facing ``depth`` shows the texture as the first view shows it, rotated by the start angle. For the
  box, ``right`` and ``depth`` then turn about ``up`` onto the object's own faces where it has some
  (``box_fits_faces``, :mod:`.faces`), so a face lies on one plane of the box. The box
  is anchored at the object's middle (its splats' median), not the world's origin: the same capture
  moved elsewhere gets the same texture, and far from the origin its texture coordinates stay precise.
- Size: the texture's height spans ``object size / repeats`` in the world, the object's size being
  what the first view sees of it (its covered pixels' box at their median depth).
- Projection (``layout_projection``): the box suits an object seen from all sides. A capture seen from
  the front (every view within ``FORWARD_SPREAD_DEG`` of the views' mean direction; ``auto``) takes the
  view projection instead: the texture thrown from the first view's centre like a slide projector, so
  every view sees it as the first does, whatever the surfaces' slopes (leaves, floors and walls at once,
  where the box cut a fern's leaves into a patchwork of planes). Like the texture bank's depth groups,
  it shows the texture ``1/r_k`` as large in the farther groups (at most ``MAX_DEPTH_RATIO``), so a
  nearer surface shows larger texture and depth edges break it.
- Normals: the rendered surface's under each splat (:mod:`.normals`), for the box's blend of its planes.
- Splats coarser than the texture's detail are split (``detail``), so a plank edge can lie
  between them, each child taking the layout's colour at its own place.
- While the GT² loss refines the look, a layout term keeps the structure: each view's render is
  matched pixel for pixel to the layout as an ideal surface shows it (``layout_images``); alone,
  the nearest-feature loss turns laid-out planks back into grain within a few hundred steps.
- Each splat samples the texture prefiltered to its own footprint (no aliasing of thin mortar
  lines into specks), the three planes blended by the normal's components to the 8th power.
- The scene under it (``keep_scene``): each splat keeps a share of the texture's brightness from the
  scene's own light and dark (``shade``), averaged over ``shade_softness`` of a repeat.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import get_args

import numpy as np
import torch
import torch.nn.functional as F

from ..cameras.camera import Camera
from ..cameras.spread import cameras_from_front
from ..cameras.warp import backproject, expected_depth
from ..errors import GT2GSError
from ..features.specs import RENDER_SCALE
from ..render import render
from ..scene.gaussians import GaussianScene
from ..scene.inria import SH_C0
from ..scene.parts import Parts, find_parts
from .accents import ColourShare, colour_share
from .bank import bank_depth_ratio
from .config import FORWARD_SPREAD_DEG, TransferConfig, keeps_scene
from .faces import turned_to_faces
from .grain import periodic_blur
from .normals import SURFACE_ALPHA, normal_map, surface_normals
from .setting import Projection
from .shade import (
    bright_end,
    coverage_weights,
    kept_scene,
    layout_shade,
    material_bright,
    shading,
    spatial_blur,
    under_scene,
)
from .texture_bank import bank_scales, screen_rotation
from .tone import luma
from .views import ViewSet

BLEND_POWER = 8.0
"""Tri-planar blend weights |n_i|^p: sharp transitions (little ghosting) that still blend at 45°."""
PREFILTER = 0.5
"""A splat samples the texture blurred by half its largest sigma (in texture pixels) ..."""
PYRAMID_LEVELS = 8
"""... from the nearest of blurs 0, 1, 2, 4, ... 64 texture pixels."""
MIN_TEXTURE_HEIGHT = 8
"""The smallest texture height the bank is built at (the config's own minimum)."""
EXTENT_QUANTILE = 0.02
"""The object's size ignores the 2 % outermost covered pixels on each side (strays, floaters)."""
NEAREST_PROJECTOR_DEPTH = 0.05
"""Points nearer the projector than this share of its nearest group's depth (or behind it) read the texture
as if at that depth, instead of an unbounded magnification."""
PROJECTIONS = get_args(Projection)


@dataclass(frozen=True)
class Projector:
    """The view projection: from ``centre`` (the first view's), a point at depth z along the frame's depth
    axis reads the texture at its right/up offsets times ``near / z``, divided by ``scales[g]`` of its depth
    group g (``depth_range`` split in ``len(scales)`` equal bins, nearest first: the texture bank's groups)."""

    centre: np.ndarray
    near: float
    depth_range: tuple[float, float]
    scales: tuple[float, ...]


@dataclass(frozen=True)
class LayoutFrame:
    """The projection's axes (rows: right, up, depth), the world size of one texture height (at the
    nearest depth group for the view projection), the view projection's projector (None: the box), the
    box's origin in the world and how far the texture slides right and up (world lengths, at that depth)."""

    axes: np.ndarray
    repeat: float
    projector: Projector | None = None
    origin: np.ndarray = field(default_factory=lambda: np.zeros(3))
    shift: tuple[float, float] = (0.0, 0.0)


def layout_frame(scene: GaussianScene, views: ViewSet, config: TransferConfig) -> LayoutFrame:
    """The layout's frame for the run's views (the first is the angle's reference): ``texture_repeats``
    texture heights across the object, or with 0 the size ``texture_height`` gives the nearest surfaces."""
    cameras = views.cameras
    up = -np.mean([c.world_to_cam[1, :3] for c in cameras], axis=0)
    if np.linalg.norm(up) < 1e-6:  # views all around a horizontal axis: the first view's own up
        up = -cameras[0].world_to_cam[1, :3]
    up = up / np.linalg.norm(up)
    first_right = cameras[0].world_to_cam[0, :3]
    right = first_right - (first_right @ up) * up
    if np.linalg.norm(right) < 1e-6:  # the first view looks along the up direction
        right = np.cross(up, cameras[0].world_to_cam[2, :3])
    right = right / np.linalg.norm(right)
    depth = np.cross(right, up)
    if depth @ cameras[0].world_to_cam[2, :3] < 0:
        depth = -depth
    axes = np.stack([right, up, depth])
    projector = _projector(views, config) if projection(cameras, config.layout_projection) == "view" else None
    if projector is None and config.box_fits_faces:
        axes = turned_to_faces(axes, views)
    if config.texture_repeats <= 0:
        repeat = config.texture_height / RENDER_SCALE * _nearest_depth(views, config.n_scales) / cameras[0].fy
    else:
        repeat = _seen_size(scene, cameras[0], config.backend) / config.texture_repeats
    shift = (config.texture_offset_right * repeat, config.texture_offset_up * repeat)
    return LayoutFrame(axes=axes, repeat=repeat, projector=projector, origin=object_middle(scene), shift=shift)


def object_middle(scene: GaussianScene) -> np.ndarray:
    """(3,) the box projection's origin: the median of the splats' centres, so the texture lies on the object
    alike wherever its capture put the world's origin (a georeferenced capture far from it included)."""
    return scene.means.detach().double().median(dim=0).values.cpu().numpy()


def projection(cameras: Sequence[Camera], choice: str) -> str:
    """``box`` or ``view``: ``choice`` itself, or for ``auto`` the view projection when every camera looks
    within ``FORWARD_SPREAD_DEG`` of the cameras' mean direction (a capture seen from the front)."""
    if choice not in PROJECTIONS:
        raise ValueError(f"layout_projection must be one of {', '.join(PROJECTIONS)}, got {choice!r}")
    if choice != "auto":
        return choice
    return "view" if cameras_from_front(cameras, FORWARD_SPREAD_DEG) else "box"


def _projector(views: ViewSet, config: TransferConfig) -> Projector:
    """The view projection's projector: the first view's centre, the depth groups the texture bank uses."""
    z = torch.cat([expected_depth(d, a, SURFACE_ALPHA)[a >= SURFACE_ALPHA] for d, a in zip(views.depths, views.alphas)])
    if not len(z):
        raise GT2GSError("no view sees the object: nothing to lay the texture on")
    groups = config.n_scales if config.depth_groups else 1
    ratio = bank_depth_ratio(views, config) if groups > 1 else 1.0
    return Projector(
        centre=np.asarray(views.cameras[0].center, np.float64),
        near=_nearest_depth(views, config.n_scales),
        depth_range=(float(z.min()), float(z.max())),
        scales=bank_scales(groups, (1.0, max(ratio, 1.0))),
    )


@torch.no_grad()
def _seen_size(scene: GaussianScene, camera: Camera, backend: str) -> float:
    """The size of ``scene`` as ``camera`` sees it: the larger side of the box around its covered
    pixels (2nd to 98th percentile) at the covered pixels' median depth, in world units. A whole
    captured scene (LLFF) measures the frame at the foreground, not its far background's extent."""
    out = render(scene.detach(), [camera], backend=backend)
    alpha, depth = out.alphas[0].cpu(), out.depths[0].cpu()
    covered = alpha >= SURFACE_ALPHA
    if not bool(covered.any()):
        raise GT2GSError("the first view does not see the object: nothing to lay the texture on")
    rows, cols = covered.nonzero(as_tuple=True)
    q = torch.tensor([EXTENT_QUANTILE, 1.0 - EXTENT_QUANTILE], dtype=torch.float64)
    height = float(torch.quantile(rows.double(), q).diff())
    width = float(torch.quantile(cols.double(), q).diff())
    surface = float(expected_depth(depth, alpha, SURFACE_ALPHA)[covered].median())
    return max(width / camera.fx, height / camera.fy, 1e-12) * surface


def texture_height_for(frame: LayoutFrame, views: ViewSet, n_scales: int) -> int:
    """The bank's texture height (pixels at the feature network's scale) that shows the layout's
    world size on the nearest depth group's surfaces, so the loss refines the texture at the size it lies."""
    pixels = frame.repeat * views.cameras[0].fy / _nearest_depth(views, n_scales) * RENDER_SCALE
    return max(MIN_TEXTURE_HEIGHT, round(pixels))


def _nearest_depth(views: ViewSet, n_scales: int) -> float:
    """The depth of the nearest depth group's centre over all views (texture_bank.depth_groups' bins)."""
    z = torch.cat([expected_depth(d, a, SURFACE_ALPHA)[a >= SURFACE_ALPHA] for d, a in zip(views.depths, views.alphas)])
    if not len(z):
        raise GT2GSError("no view sees the object: nothing to lay the texture on")
    lo, hi = float(z.min()), float(z.max())
    return max(lo + 0.5 * (hi - lo) / max(n_scales, 1), 1e-12)


def splat_normals(scene: GaussianScene, views: ViewSet, frame: LayoutFrame) -> torch.Tensor:
    """The splats' normals the frame's projection needs: the surface's for the box, none (zeros) for the view."""
    if frame.projector is not None:
        return torch.zeros(len(scene), 3, dtype=scene.dtype, device=scene.device)
    return surface_normals(scene, views.cameras, views.depths, views.alphas)


def layout_colours(
    scene: GaussianScene, normals: torch.Tensor, texture: np.ndarray, frame: LayoutFrame, angle_deg: float
) -> torch.Tensor:
    """(N, 3) RGB in [0, 1] per splat: the texture's box projection in ``frame``, rotated by
    ``angle_deg`` counter-clockwise as the first view sees it, prefiltered to each splat's footprint."""
    footprint = scene.scales.detach().max(dim=1).values
    return project_texture(scene.means.detach(), normals, texture, frame, angle_deg, footprint)


@torch.no_grad()
def layout_images(
    views: ViewSet,
    texture: np.ndarray,
    frame: LayoutFrame,
    angle_deg: float,
    shaded: bool = False,
    softness: float = 0.0,
    keep: float = 1.0,
    colour: float | ColourShare = 0.0,
    exposure: float = 1.0,
    bright: Sequence[torch.Tensor] | None = None,
    parts: Sequence[torch.Tensor] | None = None,
) -> list[torch.Tensor]:
    """Per view, the laid-out texture as an ideal surface would show it (H, W, 4: colour and coverage),
    sampled per pixel at the surface point the view's depth gives and prefiltered to a pixel's footprint:
    the structure a render of the laid-out splats only approximates (coverage 0 where the view sees no surface).
    ``shaded``: over the view's own scene as the layout lays it (:func:`under_scene`): its colour averaged over
    the surface points within about ``softness`` (a world length, by :func:`spatial_blur`), the texture times
    that colour's :func:`shading` to the power ``keep``, with ``colour`` of the colour mixed in (one share, or each
    colour's: :func:`scene_colour_mix`), the mix at the splats' ``exposure`` (:func:`laid_exposure`); the shade is
    taken against the bright end of the view's surface, or against ``bright`` (H, W per view: the luminance each
    pixel's material shows fully lit, :func:`bright_images`); each pixel's part's hue from ``parts`` (H, W, 3 per
    view: the mean colour of the part it shows, :func:`seen_images` of :func:`layout_parts`)."""
    images = []
    none = [None] * len(views.cameras)
    lit_at, parts_at = none if bright is None else bright, none if parts is None else parts
    for camera, depth, alpha, premultiplied, lit, part in zip(
        views.cameras, views.depths, views.alphas, views.premultiplied, lit_at, parts_at
    ):
        normal, _, _ = normal_map(camera, depth.cpu(), alpha.cpu())
        z = expected_depth(depth.cpu(), alpha.cpu(), SURFACE_ALPHA)
        covered = alpha.cpu() >= SURFACE_ALPHA
        points = backproject(z, camera)[covered].float()
        pixel = float(z[covered].median()) / camera.fy if bool(covered.any()) else 0.0
        colours = project_texture(points, normal[covered].float(), texture, frame, angle_deg, pixel)
        if shaded:
            weight = alpha.cpu()[covered].float()
            seen = (premultiplied.cpu()[covered].float() / weight[:, None]).clamp(0.0, 1.0)
            if softness > 0:  # the same average as the splats' shade
                seen = torch.stack([spatial_blur(points, seen[:, c], weight, softness) for c in range(3)], dim=1)
            full = None if lit is None else lit.cpu()[covered].float()
            of_parts = None if part is None else part.cpu()[covered].float()
            kept = kept_scene(shading(luma(seen), keep=keep, bright=full), seen, colour, exposure, of_parts)
            colours = under_scene(colours, kept)
        image = torch.zeros(camera.height, camera.width, 4)
        image[covered] = torch.cat([colours.float(), torch.ones(len(colours), 1)], dim=1)
        images.append(image.to(depth.device))
    return images


def project_texture(
    points: torch.Tensor,
    normals: torch.Tensor,
    texture: np.ndarray,
    frame: LayoutFrame,
    angle_deg: float,
    footprint: torch.Tensor | float,
) -> torch.Tensor:
    """(N, 3) RGB of the frame's projection at world ``points`` with ``normals`` (the box blends its planes
    by them; the view projection ignores them); each point reads the texture blurred by ``PREFILTER`` x its
    ``footprint`` (a world length, per point or one for all) as the projection scales it, the nearest of a
    pyramid of blurs (periodic, as the texture tiles), so nothing finer than a splat aliases and nothing coarser
    is lost."""
    height = texture.shape[0]
    world_per_px = frame.repeat / height
    planes, scale = _planes(points, normals, frame)
    blur = PREFILTER * torch.as_tensor(footprint, dtype=scale.dtype, device=scale.device) * scale / world_per_px
    level = torch.log2(blur.clamp_min(0.5) / 0.5).round().clamp(0, PYRAMID_LEVELS - 1).long().expand(len(points))
    colours = torch.zeros(len(points), 3, dtype=scale.dtype, device=scale.device)
    for k in level.unique().tolist():
        rows = (level == k).nonzero().squeeze(1)
        image = periodic_blur(texture, 0.5 * 2.0**k) if k > 0 else texture
        for h, v, weight in planes:
            sampled = _sample(image, h[rows] / world_per_px, -v[rows] / world_per_px, angle_deg)
            colours[rows] += weight[rows, None] * sampled
    return colours.clamp(0.0, 1.0)


def _planes(
    points: torch.Tensor, normals: torch.Tensor, frame: LayoutFrame
) -> tuple[list[tuple[torch.Tensor, ...]], torch.Tensor]:
    """The projection's (horizontal, vertical, weight) texture coordinates per plane (world lengths at the
    repeat's scale, the texture slid by the frame's shift), and per point how much the projection magnifies a
    world length there."""
    axes = torch.from_numpy(frame.axes).to(points)
    right, up = frame.shift
    if frame.projector is not None:
        p = frame.projector
        local = (points - torch.from_numpy(p.centre).to(points)) @ axes.T
        z = local[:, 2].clamp_min(NEAREST_PROJECTOR_DEPTH * p.near)
        lo, hi = p.depth_range
        bins = len(p.scales)
        group = ((z - lo) / max(hi - lo, 1e-12) * bins).floor().clamp(0, bins - 1).long()
        scale = p.near / z / torch.tensor(p.scales, dtype=points.dtype, device=points.device)[group]
        return [(local[:, 0] * scale - right, local[:, 1] * scale - up, torch.ones_like(scale))], scale
    local = (points - torch.from_numpy(frame.origin).to(points)) @ axes.T  # (N, 3): right, up, depth
    local = local - torch.tensor([right, up, 0.0], dtype=local.dtype, device=local.device)  # the box slid along
    facing = (normals.to(local) @ axes.T).abs().pow(BLEND_POWER)
    weights = facing / facing.sum(dim=1, keepdim=True).clamp_min(1e-12)
    planes = [  # the planes facing right, up and depth
        (local[:, 2], local[:, 1], weights[:, 0]),
        (local[:, 0], local[:, 2], weights[:, 1]),
        (local[:, 0], local[:, 1], weights[:, 2]),
    ]
    return planes, torch.ones(len(points), dtype=points.dtype, device=points.device)


def _sample(texture: np.ndarray, x: torch.Tensor, y: torch.Tensor, angle_deg: float) -> torch.Tensor:
    """Bilinear, wrapped samples of ``texture`` at texture-pixel coordinates (x right, y down),
    the texture turned ``angle_deg`` counter-clockwise on screen (texture_bank's convention)."""
    (c, s), _ = screen_rotation(angle_deg).tolist()
    tx, ty = c * x - s * y, s * x + c * y  # the inverse (transpose) of the on-screen rotation [[c, s], [-s, c]]
    height, width = texture.shape[:2]
    # one texel of the next repeat on each side, so a point by an edge blends into it (grid_sample cannot wrap)
    wrapped = np.pad(texture, ((1, 1), (1, 1), (0, 0)), mode="wrap")
    grid = torch.stack(
        [
            (torch.remainder(tx, width) + 1) / (width + 2) * 2 - 1,
            (torch.remainder(ty, height) + 1) / (height + 2) * 2 - 1,
        ],
        -1,
    )
    image = torch.from_numpy(wrapped).permute(2, 0, 1)[None].to(x)
    sampled = F.grid_sample(image, grid[None, None], mode="bilinear", padding_mode="border", align_corners=False)
    return sampled[0, :, 0].T


def with_colours(scene: GaussianScene, rgb: torch.Tensor, rows: torch.Tensor | None = None) -> GaussianScene:
    """``scene`` whose DC colour is ``rgb`` (N, 3) (only on ``rows`` when given) and rest bands zero there."""
    dc = ((rgb - 0.5) / SH_C0).to(scene.sh_dc)
    if rows is None:
        return replace(scene, sh_dc=dc, sh_rest=torch.zeros_like(scene.sh_rest))
    return replace(
        scene,
        sh_dc=torch.where(rows[:, None], dc, scene.sh_dc),
        sh_rest=torch.where(rows[:, None, None], torch.zeros_like(scene.sh_rest), scene.sh_rest),
    )


def lay_out(
    scene: GaussianScene,
    rows: torch.Tensor | None,
    views: ViewSet,
    texture: np.ndarray,
    frame: LayoutFrame,
    config: TransferConfig,
    shade: torch.Tensor | None = None,
) -> GaussianScene:
    """``scene`` with the texture laid on ``rows`` (all when None) in ``frame``, over the scene each splat keeps
    (``shade``, :func:`layout_shade`; None: the texture's own colours): what the optimisation starts from."""
    part = scene if rows is None else scene.subset(rows)
    colours = layout_colours(part, splat_normals(part, views, frame), texture, frame, config.angle)
    if shade is not None:
        colours = under_scene(colours, shade if rows is None else shade[rows])
    laid = with_colours(part, colours)
    if rows is None:
        return laid
    index = rows.nonzero().squeeze(1)
    return replace(
        scene,
        sh_dc=scene.sh_dc.index_copy(0, index, laid.sh_dc),
        sh_rest=scene.sh_rest.index_copy(0, index, laid.sh_rest),
    )


def layout_shading(
    scene: GaussianScene,
    rows: torch.Tensor | None,
    frame: LayoutFrame,
    config: TransferConfig,
    texture: np.ndarray,
    mix: float | ColourShare,
    bright: torch.Tensor | None = None,
    parts: torch.Tensor | None = None,
) -> torch.Tensor | None:
    """What of the scene a run with ``config`` lays ``texture`` over (:func:`layout_shade`, ``shade_softness``
    repeats of ``frame``, ``keep_scene``, the colour ``mix`` of :func:`scene_colour_mix`, ``scene_brightness``,
    the shade against ``bright`` (:func:`layout_bright`), the parts' hues of ``parts`` (:func:`layout_parts`)),
    or None when it keeps the texture's own colours. *Scene Brightness* keeps only ``keep_material`` of its
    exposure (in stops): a part given the texture's brightness is not darkened back."""
    if not keeps_scene(config):
        return None
    width = shade_width(frame, config)
    brightness = config.scene_brightness * config.keep_material
    return layout_shade(scene, rows, width, config.keep_scene, mix, texture, brightness, bright, parts)


def scene_colour_mix(scene: GaussianScene, rows: torch.Tensor | None, config: TransferConfig) -> float | ColourShare:
    """How much of its own colour each part of ``scene`` keeps under the texture (:func:`colour_share`):
    ``scene_colour``, raised by ``keep_accents`` for the rare, vivid colours among the splats of ``rows`` (all when
    None) as they cover a view, and ``keep_hues`` of each one's part's hue (:func:`layout_parts`), when the run
    keeps anything of the scene (else the texture alone)."""
    if not keeps_scene(config) or (config.keep_accents <= 0 and config.keep_hues <= 0):
        return config.scene_colour
    part = slice(None) if rows is None else rows
    weights = coverage_weights(scene.scales.detach()[part], scene.opacities.detach()[part])
    colours = scene.base_colors.detach()[part].clamp(0.0, 1.0)
    return colour_share(colours, weights, config.scene_colour, config.keep_accents, config.keep_hues)


def layout_materials(
    scene: GaussianScene, rows: torch.Tensor | None, config: TransferConfig
) -> tuple[torch.Tensor | None, torch.Tensor | None]:
    """(:func:`layout_bright`, :func:`layout_parts`) of ``scene``, its parts found once for both (each None where its
    setting keeps nothing)."""
    wanted = keeps_scene(config) and (config.keep_material < 1.0 or config.keep_hues > 0.0)
    found = find_parts(scene) if wanted else None
    return layout_bright(scene, rows, config, found), layout_parts(scene, config, found)


def layout_bright(
    scene: GaussianScene, rows: torch.Tensor | None, config: TransferConfig, found: Parts | None = None
) -> torch.Tensor | None:
    """(N,) the luminance each splat's material shows fully lit (:func:`material_bright` over the parts
    ``find_parts`` finds, or ``found``, among the splats of ``rows``; the others take the bright end), or None with
    ``keep_material`` 1 (the whole scene's bright end, as the shade takes it then)."""
    if config.keep_material >= 1.0 or not keeps_scene(config):
        return None
    colours = scene.base_colors.detach().clamp(0.0, 1.0)
    luminance = luma(colours)
    labels = torch.from_numpy((found if found is not None else find_parts(scene)).labels).to(luminance.device)
    part = torch.ones_like(labels, dtype=torch.bool) if rows is None else rows.to(labels.device)
    bright = torch.full_like(luminance, bright_end(luminance[part]))
    bright[part] = material_bright(luminance[part], labels[part], config.keep_material)
    return bright


def layout_parts(scene: GaussianScene, config: TransferConfig, found: Parts | None = None) -> torch.Tensor | None:
    """(N, 3) the mean colour of the part ``find_parts`` (or ``found``) puts each splat in, whose hue *Keep Hues*
    keeps, or None with ``keep_hues`` 0 (or when the run keeps nothing of the scene)."""
    if config.keep_hues <= 0.0 or not keeps_scene(config):
        return None
    parts = found if found is not None else find_parts(scene)
    return torch.from_numpy(parts.colours[parts.labels]).to(scene.means)


def bright_images(scene: GaussianScene, views: ViewSet, bright: torch.Tensor, backend: str) -> list[torch.Tensor]:
    """(H, W) per view: ``bright`` (N, :func:`layout_bright`) as the view sees the splats, blended as their
    colours are, so a pixel's shade is taken against the material it shows."""
    return [image[..., 0] for image in seen_images(scene, views, bright[:, None].expand(-1, 3), backend)]


@torch.no_grad()
def seen_images(scene: GaussianScene, views: ViewSet, values: torch.Tensor, backend: str) -> list[torch.Tensor]:
    """(H, W, 3) per view: the splats' ``values`` (N, 3) as the view sees them, blended as their colours are."""
    values = values.to(scene.means).contiguous()
    images = []
    for camera in views.cameras:
        out = render(scene.detach(), [camera], colors=values, render_depth=False, backend=backend)
        images.append(out.colors[0] / out.alphas[0].clamp_min(1e-6)[..., None])
    return images


def shade_width(frame: LayoutFrame, config: TransferConfig) -> float:
    """The world width the kept light and shade is averaged over: ``shade_softness`` repeats of ``frame``."""
    return config.shade_softness * frame.repeat
