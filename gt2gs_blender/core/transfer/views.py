"""The run's views: cameras fitted to the scene, the original's renders from them, and the per-view
targets the stylise phases match (content image, backdrop, covered cells, depth groups, AFCM level)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import torch

from ..cameras.camera import Camera
from ..cameras.cut import cut_to_scene
from ..cameras.generate import auto_views
from ..errors import GT2GSError
from ..features.extractor import FeatureExtractor
from ..render import render
from ..scene.gaussians import GaussianScene
from .config import TransferConfig
from .stylise import ViewTargets, frequency_levels
from .texture_bank import cell_groups, covered_cells, depth_groups

OBJECT_ALPHA = 0.9
"""Pixels above this alpha count as the object's own colour for the stylise backdrop."""


@dataclass
class ViewSet:
    """The run's cameras and the original scene's renders from them (no gradients)."""

    cameras: list[Camera]
    premultiplied: list[torch.Tensor]  # (H,W,3) colour over black
    alphas: list[torch.Tensor]  # (H,W)
    depths: list[torch.Tensor]  # (H,W) expected depth sum(T alpha z)
    background: torch.Tensor  # (3,)

    def composited(self, v: int, background: torch.Tensor | None = None) -> torch.Tensor:
        """View ``v`` over ``background`` (3,) (None: the run's background)."""
        backdrop = self.background if background is None else background
        return self.premultiplied[v] + (1.0 - self.alphas[v][..., None]) * backdrop

    def object_colour(self, min_alpha: float = OBJECT_ALPHA) -> torch.Tensor:
        """Mean colour (3,) of the pixels the object covers (alpha above ``min_alpha``) in all views;
        the background colour when it covers none."""
        colours = [p[a > min_alpha] / a[a > min_alpha][:, None] for p, a in zip(self.premultiplied, self.alphas)]
        covered = torch.cat(colours) if colours else torch.zeros(0, 3)
        return covered.mean(0).clamp(0.0, 1.0) if len(covered) else self.background.clone()

    def subset(self, keep: Sequence[int]) -> ViewSet:
        """The views ``keep`` (indices, in that order)."""
        return ViewSet(
            [self.cameras[v] for v in keep],
            [self.premultiplied[v] for v in keep],
            [self.alphas[v] for v in keep],
            [self.depths[v] for v in keep],
            self.background,
        )


def fit_cameras(
    scene: GaussianScene,
    views: Sequence[Camera] | int | None,
    resolution: int,
    n_default: int,
    up: str = "+z",
    *,
    kind: str = "orbit",
    cut: bool = False,
) -> list[Camera]:
    """Automatic views (a count or None) of ``kind`` (``auto_views``'s) about the ``up`` axis, framed in
    ``resolution`` squares (``cut``: and cut to the splats, so a tall or wide object is not rendered with empty
    bands), or the given cameras resized so their longest side is ``resolution``."""
    if isinstance(views, int) and views < 1:
        raise GT2GSError(f"views: at least 1 automatic view, got {views}")
    if views is None or isinstance(views, int):
        count = n_default if views is None else views
        framed = auto_views(scene, count, width=resolution, height=resolution, kind=kind, up=up)
        return cut_to_scene(framed, scene) if cut else framed
    cameras = list(views)
    if not cameras:
        raise GT2GSError("no views given: pass cameras or a number of automatic views")
    return [cam.scaled(resolution / max(cam.width, cam.height)) for cam in cameras]


@torch.no_grad()
def render_views(
    scene: GaussianScene,
    cameras: Sequence[Camera],
    background: torch.Tensor,
    backend: str,
    sh_degree: int | None = None,
) -> ViewSet:
    """Render every camera once (colour over black, alpha, depth), SH up to ``sh_degree`` (None = all)."""
    premultiplied, alphas, depths = [], [], []
    for cam in cameras:
        out = render(scene, [cam], backend=backend, sh_degree=sh_degree)
        premultiplied.append(out.colors[0])
        alphas.append(out.alphas[0])
        depths.append(out.depths[0])
    return ViewSet(list(cameras), premultiplied, alphas, depths, background)


def to_nchw(image: torch.Tensor) -> torch.Tensor:
    return image.permute(2, 0, 1)[None]


@torch.no_grad()
def view_targets(
    views: ViewSet, start: GaussianScene, extractor: FeatureExtractor, config: TransferConfig, backend: str
) -> list[ViewTargets]:
    """Per view: the content image (the colour-transferred start's render), the backdrop the stylise
    phases render over and the content features over it, the covered cells, each cell's depth group
    and the AFCM frequency level (of the content image: an outline is detail to keep)."""
    start_views = render_views(start, views.cameras, views.background, backend)
    images = [start_views.composited(v) for v in range(len(views.cameras))]
    backdrop = start_views.object_colour() if config.object_backdrop else views.background
    feats = [extractor(to_nchw(start_views.composited(v, backdrop))) for v in range(len(images))]
    masks = [
        covered_cells(views.alphas[v], tuple(feats[v].shape[-2:]), fraction=config.cell_coverage)
        for v in range(len(feats))
    ]
    groups: list[torch.Tensor | None] = [None] * len(feats)
    if config.depth_groups and config.n_scales > 1:
        # all views at once, so a surface falls in the same depth group in every view
        pixel_groups = depth_groups(torch.stack(views.depths), torch.stack(views.alphas), config.n_scales)
        groups = [cell_groups(pixel_groups[v], tuple(feats[v].shape[-2:])) for v in range(len(feats))]
    levels = frequency_levels(images, masks)
    return [
        ViewTargets(cam, image, backdrop, f, m, g, level)
        for cam, image, f, m, g, level in zip(views.cameras, images, feats, masks, groups, levels)
    ]
