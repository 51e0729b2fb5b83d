"""Adaptive density control of 3DGS: grow where the image gradient is large, drop what is useless.

Per Gaussian we accumulate a screen-space gradient norm over the views that see it, from one of two
sources: ``position`` = |dL/d(2D mean)| in normalised device coordinates, as 3DGS does (so its
threshold 2e-4 applies unchanged), or ``color`` = |dL/d f_dc|, as the GT2-GS authors densify while
stylising (only colours learn then). Above the threshold, small Gaussians are cloned and large
ones split into N children with scales / (0.8 N), sampled from the parent (a parent whose children
would not be finite, e.g. of scale exp(100), is kept unsplit and counted instead). Prune: nearly
transparent ones, and (later in training) ones too large on screen or in the world. Frozen
Gaussians are never densified, pruned or reset. Every change goes through
:meth:`GaussianAdam.restructure`, so parameters, Adam moments, masks and statistics stay aligned.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import torch

from ..render.projection import Footprints
from ..scene.gaussians import quats_to_rotmats
from .optim import GaussianAdam

GRAD_SOURCES = ("position", "color")
log = logging.getLogger(__name__)


def _check_source(source: str) -> str:
    if source not in GRAD_SOURCES:
        raise ValueError(f"unknown densification gradient source {source!r}; use one of {GRAD_SOURCES}")
    return source


@dataclass(frozen=True)
class DensifyConfig:
    """3DGS's density-control settings (defaults = the paper's)."""

    grad_threshold: float = 2e-4
    grad_source: str = "position"
    percent_dense: float = 0.01
    """Gaussians larger than this fraction of the scene extent are split, smaller ones cloned."""
    clone: bool = True
    """Clone the small ones. A clone sits on its parent and only moves apart where the positions learn; while
    only colours learn it is the same splat twice, more opaque and no finer, so a colour-only run turns it off."""
    split_count: int = 2
    min_opacity: float = 0.005
    max_screen_radius: float = 20.0
    """Pixels; with ``max_world_scale`` (fraction of the extent), applied only when asked to prune large."""
    max_world_scale: float = 0.1
    reset_opacity: float = 0.01

    def __post_init__(self) -> None:
        _check_source(self.grad_source)


@dataclass(frozen=True)
class DensifyReport:
    """What one densification step did."""

    cloned: int
    split: int
    pruned: int
    total: int
    unsplit: int = 0
    """Gaussians due a split whose children would not be finite (absurd scales or positions): kept as they were."""


class DensityStats:
    """Per-Gaussian accumulated gradient norm, number of views seen in, and largest screen radius."""

    def __init__(self, n: int, source: str = "position", device: torch.device | str | None = None) -> None:
        self.source = _check_source(source)
        self.grad_sum = torch.zeros(n, dtype=torch.float64, device=device)
        self.count = torch.zeros(n, dtype=torch.int64, device=device)
        self.max_radius = torch.zeros(n, dtype=torch.float32, device=device)

    def __len__(self) -> int:
        return int(self.count.shape[0])

    def add(self, footprints: Footprints, width: int, height: int, sh_dc_grad: torch.Tensor | None) -> None:
        """Add one step's statistics, after backward. ``position`` needs ``footprints.means2d.grad``
        (call ``retain_grad()`` on it before backward); ``color`` needs the f_dc gradient (N, 3)."""
        ids = footprints.gauss_ids
        if self.source == "position":
            if footprints.means2d.grad is None:
                return
            ndc = footprints.means2d.grad.detach() * torch.tensor(
                [width / 2.0, height / 2.0], dtype=footprints.means2d.dtype, device=ids.device
            )
            self.grad_sum.index_add_(0, ids, ndc.norm(dim=-1).double())
            self.count.index_add_(0, ids, torch.ones_like(ids))
        else:
            if sh_dc_grad is None:
                return
            seen = torch.unique(ids)
            self.grad_sum.index_add_(0, seen, sh_dc_grad.detach()[seen].norm(dim=-1).double())
            self.count.index_add_(0, seen, torch.ones_like(seen))
        radius = footprints.radii.detach().max(dim=-1).values.float()
        self.max_radius.scatter_reduce_(0, ids, radius, reduce="amax")

    def mean_grad(self) -> torch.Tensor:
        """Average gradient norm over the views each Gaussian was seen in (0 if never seen)."""
        return self.grad_sum / self.count.clamp_min(1)

    def restructure(self, source: torch.Tensor, n_kept: int) -> None:
        """Follow :meth:`GaussianAdam.restructure`: survivors keep their statistics, new rows start at 0."""
        for name in ("grad_sum", "count", "max_radius"):
            t = getattr(self, name)[source]
            t[n_kept:] = 0
            setattr(self, name, t)

    def reset(self) -> None:
        for t in (self.grad_sum, self.count, self.max_radius):
            t.zero_()


def apply_structure(
    opt: GaussianAdam,
    stats: DensityStats,
    keep: torch.Tensor,
    parents: torch.Tensor,
    values: dict[str, torch.Tensor] | None = None,
) -> None:
    """Keep the rows ``keep`` (bool) and append children of ``parents`` (with ``values`` overriding
    their tensors), in the optimiser and the statistics alike."""
    kept = keep.nonzero().squeeze(1)
    source = torch.cat([kept, parents.to(kept.device)])
    opt.restructure(source, len(kept), values)
    stats.restructure(source, len(kept))


def densify_due(step: int, every: int, after: int = 0) -> bool:
    """Whether densification runs at ``step`` (counted from 1): every ``every`` steps once past step ``after``,
    the 3DGS schedule photo fitting and the stylise phases share (each within its own window)."""
    return step > after and step % every == 0


def densify_and_prune(
    opt: GaussianAdam,
    stats: DensityStats,
    config: DensifyConfig,
    extent: float,
    *,
    prune_large: bool,
    generator: torch.Generator | None = None,
) -> DensifyReport:
    """One density-control step: clone, split and prune by the accumulated statistics, then reset them."""
    scene = opt.scene.detach()
    max_scale = scene.scales.max(dim=-1).values
    prune = scene.opacities < config.min_opacity
    if prune_large:
        prune |= (stats.max_radius > config.max_screen_radius) | (max_scale > config.max_world_scale * extent)
    prune &= ~opt.frozen
    grow = (stats.mean_grad() >= config.grad_threshold) & ~opt.frozen & ~prune
    small = max_scale <= config.percent_dense * extent
    clone_ids = (grow & small & config.clone).nonzero().squeeze(1)
    split_parents = (grow & ~small).nonzero().squeeze(1)
    count = config.split_count
    means, log_scales = _split_children(
        scene.means, scene.quats, scene.log_scales, split_parents.repeat_interleave(count), count, generator
    )
    finite = (torch.isfinite(means).all(dim=-1) & torch.isfinite(log_scales).all(dim=-1)).view(-1, count).all(dim=-1)
    unsplit = int((~finite).sum())
    if unsplit:
        log.warning(
            "densify: %d Gaussians were not split because their children's positions or scales would not "
            "be finite (absurd scales); they are kept as they are",
            unsplit,
        )
        children = finite.repeat_interleave(count)
        split_parents, means, log_scales = split_parents[finite], means[children], log_scales[children]
    values = {
        "means": torch.cat([scene.means[clone_ids], means]),
        "log_scales": torch.cat([scene.log_scales[clone_ids], log_scales]),
    }
    keep = ~prune
    keep[split_parents] = False
    apply_structure(opt, stats, keep, torch.cat([clone_ids, split_parents.repeat_interleave(count)]), values)
    stats.reset()
    return DensifyReport(
        cloned=len(clone_ids), split=len(split_parents), pruned=int(prune.sum()), total=len(opt.scene), unsplit=unsplit
    )


def _split_children(
    means: torch.Tensor,
    quats: torch.Tensor,
    log_scales: torch.Tensor,
    ids: torch.Tensor,
    count: int,
    generator: torch.Generator | None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Children of the parents ``ids`` (each listed ``count`` times): positions sampled from the
    parent Gaussian, scales divided by 0.8 * count (3DGS's 1.6 for two children)."""
    scales = log_scales[ids].exp()
    drawn_on = scales.device if generator is None else generator.device  # a generator draws on its own device
    noise = torch.randn(scales.shape, generator=generator, dtype=scales.dtype, device=drawn_on).to(scales.device)
    offsets = (quats_to_rotmats(quats[ids]) @ (noise * scales)[..., None])[..., 0]
    return means[ids] + offsets, log_scales[ids] - math.log(0.8 * count)


def reset_opacity(opt: GaussianAdam, value: float) -> None:
    """Cap every unfrozen Gaussian's opacity at ``value`` (3DGS's periodic reset, which lets
    training re-decide what is needed) and restart their opacity moments."""
    rows = ~opt.frozen
    logits = opt.scene.opacity_logits.detach()
    cap = math.log(value / (1.0 - value))
    opt.assign("opacity_logits", rows, logits[rows].clamp(max=cap))
