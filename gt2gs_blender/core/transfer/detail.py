"""Splats split to the texture's detail: at the donut's 45k splats no plank shows; at ~320k they do.

Before the optimisation (``split_first``), or after it on the scene's own splats (faster: the time grows
with their count), splats coarser than ``split_size`` of a repeat are split in two along each of their two
largest axes that is (2 x 2 in their plane; 1 x 2 along a needle, which grows rounder instead of thinner;
children drawn to look like their parent: :func:`child_opacity`), at most
``SPLIT_PASSES`` times and within ``split_budget`` times the splats, so a plank edge can lie between
splats. Each child takes the layout's colour at its place (and, after the optimisation, what it changed
on its parent).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import replace

import numpy as np
import torch

from ..scene.gaussians import GaussianScene, concat, quats_to_rotmats
from ..scene.inria import SH_C0
from .config import TransferConfig
from .layout import LayoutFrame, layout_colours, splat_normals
from .shade import under_scene
from .views import ViewSet

SPLIT_OFFSET = 0.6
"""Children sit at +-0.6 sigma along each split axis ..."""
SPLIT_SHRINK = 0.6
"""... with 0.6 of its scale there. Placed at 0.8 sigma, which keeps the parent's second moment, their alpha
had two humps and 1.2x the parent's opacity per axis (the guitar's render kept SSIM 0.85 of itself after the
split, 0.89 now); at 0.6 sigma with :func:`child_opacity` they come closest to their parent's shape."""
SPLIT_PASSES = 3
"""At most three splits (up to 64 children) per splat."""


def split_limit(count: int, config: TransferConfig) -> int:
    """The most splats the detail split may leave of ``count`` restyled ones: ``split_budget`` times as many."""
    return math.floor(config.split_budget * count)


def split_coarse(scene: GaussianScene, max_sigma: float, max_count: int) -> tuple[GaussianScene, torch.Tensor]:
    """Split splats whose largest sigma exceeds ``max_sigma`` in two along each of their two largest axes
    that does (2 x 2 in their plane, 1 x 2 along a needle), up to ``SPLIT_PASSES`` times and while the
    scene stays within ``max_count`` splats (largest first).

    Returns the scene (unsplit splats first, in order, then the children) and each row's source row."""
    source = torch.arange(len(scene), device=scene.device)
    for _ in range(SPLIT_PASSES):
        top = scene.scales.detach().sort(dim=1, descending=True, stable=True).values
        coarse = top[:, 0] > max_sigma
        both = coarse & (top[:, 1] > max_sigma)
        room = max_count - len(scene)
        if room <= 0 or not bool(coarse.any()):
            break
        order = torch.sort(top[:, 0], descending=True, stable=True).indices  # ties by row, on every device
        extra = (torch.where(both, 3, 1) * coarse)[order]
        chosen = order[coarse[order] & (torch.cumsum(extra, 0) <= room)]
        split = torch.zeros_like(coarse).index_fill_(0, chosen, True)
        quads, pairs = (split & both).nonzero().squeeze(1), (split & ~both).nonzero().squeeze(1)
        children = [_split_along(scene.subset(quads), 2), _split_along(scene.subset(pairs), 1)]
        scene = concat([scene.subset(~split), *children])
        source = torch.cat([source[~split], source[quads].repeat(4), source[pairs].repeat(2)])
    return scene, source


def child_opacity(offset: float = SPLIT_OFFSET, shrink: float = SPLIT_SHRINK) -> float:
    """The share of its parent's opacity each child keeps per axis split: the least-squares fit of two children
    (at +-``offset`` sigma, ``shrink`` of the scale) to the parent's alpha where splats are faint and their
    alphas add, in closed form (Gaussian products). A 2 x 2 split takes it twice (the children are separable);
    for an opaque parent, whose children's alphas saturate, the best share is up to 10 % higher, and this one
    draws within 0.025 of its error (relative L2)."""
    shrink2 = shrink * shrink
    overlap = math.sqrt(2.0 / (1.0 + shrink2)) * math.exp(-offset * offset / (2.0 * (1.0 + shrink2)))
    return overlap / (1.0 + math.exp(-offset * offset / shrink2))


def _split_along(parents: GaussianScene, n_axes: int) -> GaussianScene:
    """2^n_axes children per parent, halving it along its ``n_axes`` largest axes, each with ``child_opacity``
    of its opacity per axis (module notes)."""
    scales = parents.scales.detach()
    rot = quats_to_rotmats(parents.rotations.detach())
    order = scales.argsort(dim=1, descending=True, stable=True)  # equal axes: by index, on every device
    rows = torch.arange(len(parents), device=parents.device)
    axes = [rot[rows, :, order[:, k]] * scales[rows, order[:, k]][:, None] for k in range(n_axes)]
    shrink = torch.zeros_like(scales)
    for k in range(n_axes):
        shrink[rows, order[:, k]] = math.log(SPLIT_SHRINK)
    share = child_opacity() ** n_axes
    # logit(share * sigmoid(l)) = log(share) - log(1 - share + e^-l), finite for every finite l
    logits = math.log(share) - torch.logaddexp(
        torch.full_like(parents.opacity_logits, math.log1p(-share)), -parents.opacity_logits
    )
    kids = []
    for signs in itertools.product((-1, 1), repeat=n_axes):
        offset = SPLIT_OFFSET * sum(sign * axis for sign, axis in zip(signs, axes, strict=True))
        kids.append(
            replace(
                parents, means=parents.means + offset, log_scales=parents.log_scales + shrink, opacity_logits=logits
            )
        )
    return concat(kids)


def split_for_detail(
    scene: GaussianScene,
    rows: torch.Tensor | None,
    shade: torch.Tensor | None,
    frame: LayoutFrame,
    config: TransferConfig,
) -> tuple[GaussianScene, torch.Tensor | None, torch.Tensor | None]:
    """``scene`` with ``rows`` (all when None) split where coarser than ``split_size`` repeats, before the
    optimisation: the split rows move to the end; returns the scene, the new rows mask and ``shade`` per row."""
    part = scene if rows is None else scene.subset(rows)
    fine, source = split_coarse(part, config.split_size * frame.repeat, split_limit(len(part), config))
    if shade is not None:
        shade = shade[source] if rows is None else torch.cat([shade[~rows], shade[rows][source]])
    return *_rejoin(scene, rows, fine), shade


def _rejoin(
    scene: GaussianScene, rows: torch.Tensor | None, fine: GaussianScene
) -> tuple[GaussianScene, torch.Tensor | None]:
    """``scene``'s splats outside ``rows`` (in order) then ``fine``, the split ``rows`` (all of it when None),
    and the new rows mask (None when all)."""
    if rows is None:
        return fine, None
    kept = scene.subset(~rows)
    mask = torch.cat([torch.zeros(len(kept), dtype=torch.bool), torch.ones(len(fine), dtype=torch.bool)])
    return concat([kept, fine]), mask.to(scene.device)


def add_detail(
    scene: GaussianScene,
    start_colours: torch.Tensor,
    rows: torch.Tensor | None,
    views: ViewSet,
    texture: np.ndarray,
    frame: LayoutFrame,
    config: TransferConfig,
    shade: torch.Tensor | None = None,
) -> tuple[GaussianScene, torch.Tensor | None]:
    """The optimised ``scene`` at the texture's detail: ``rows`` (all when None) split where coarser
    than ``split_size`` repeats, each child coloured by the layout at its own place over its parent's kept
    scene ``shade`` (as :func:`lay_out` laid it) plus what the optimisation changed on its parent (its colour
    minus ``start_colours``). The split rows move to the end; returns the scene and the new rows mask."""
    part = scene if rows is None else scene.subset(rows)
    change = part.base_colors - (start_colours if rows is None else start_colours[rows]).to(part.sh_dc)
    fine, source = split_coarse(part, config.split_size * frame.repeat, split_limit(len(part), config))
    colours = layout_colours(fine, splat_normals(fine, views, frame), texture, frame, config.angle)
    if shade is not None:
        colours = under_scene(colours, (shade if rows is None else shade[rows])[source])
    colours = colours + change[source]
    fine = replace(fine, sh_dc=((colours.clamp(0.0, 1.0) - 0.5) / SH_C0).to(fine.sh_dc))
    return _rejoin(scene, rows, fine)
