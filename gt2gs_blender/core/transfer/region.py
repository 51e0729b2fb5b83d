"""Region control and the result's assembly: which Gaussians are restyled, what they start from,
and how restyled, frozen and hidden Gaussians are put back together in a stable order."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import torch

from ..errors import GT2GSError
from ..scene.gaussians import GaussianScene, concat
from .stylise import StyliseStats


def structure_changed(stats: StyliseStats) -> bool:
    """Whether densification added or removed any Gaussian during the run."""
    return any(d["cloned"] or d["split"] or d["pruned"] for d in stats.densified)


def assemble(
    work: GaussianScene,
    restyled: torch.Tensor | None,
    start: GaussianScene,
    selected: torch.Tensor | None,
    hidden: torch.Tensor | None,
    changed: bool,
) -> GaussianScene:
    """The result from the optimised ``work`` scene and ``start`` (every input Gaussian as the run
    began: at the result's SH degree, before colour transfer), whose hidden rows come back as they are.
    Without a region: the original order when the hidden rows can go back to their places (no
    densification), else the hidden rows first. With a region: the Gaussians outside it first, in
    their original order, then the region's hidden ones, then the restyled ones (and any densified)."""
    if hidden is None and selected is None:
        return work
    if selected is None:
        if changed:
            return concat([start.subset(hidden), work])
        rows = (~hidden).nonzero().squeeze(1)
        return replace(start, **{k: v.index_copy(0, rows, work.tensors()[k]) for k, v in start.tensors().items()})
    parts = [start.subset(~selected)] + ([] if hidden is None else [start.subset(selected & hidden)])
    return concat([*parts, work.subset(restyled)])


def visible_rows(
    selected: torch.Tensor | None, hidden: torch.Tensor | None
) -> tuple[torch.Tensor | None, torch.Tensor | None]:
    """The hidden rows a run skips (None when none, or when every selected row is hidden: then it restyles
    them as asked) and the region among the rest (None: all of them)."""
    if hidden is not None and selected is not None and not bool((selected & ~hidden).any()):
        hidden = None
    return hidden, selected if selected is None or hidden is None else selected[~hidden]


def region_mask(region: torch.Tensor | np.ndarray | None, n: int, device: torch.device) -> torch.Tensor | None:
    """The region as a bool mask (n,) on ``device`` (from a mask or an index array); None = everything."""
    if region is None:
        return None
    region = torch.as_tensor(np.asarray(region) if not isinstance(region, torch.Tensor) else region)
    problem = region_problem(region, n)
    if problem is not None:
        raise GT2GSError(f"the region {problem}")
    if region.dtype == torch.bool:
        return region.to(device)
    return torch.zeros(n, dtype=torch.bool).index_fill_(0, region.long().reshape(-1), True).to(device)


def region_problem(region: torch.Tensor | np.ndarray, n: int) -> str | None:
    """Why ``region`` (a bool mask or an index array) cannot select Gaussians of a scene of ``n``, as the end of
    a sentence about it ('selects none: ...'), else None: the one rule the engine and a region file's reader use."""
    region = torch.as_tensor(np.asarray(region) if not isinstance(region, torch.Tensor) else region)
    if region.dtype == torch.bool:
        if region.shape != (n,):
            return f"mask has {tuple(region.shape)} entries for a scene of {n} Gaussians (one per Gaussian)"
        selected = bool(region.any())
    else:
        index = region.long().reshape(-1)
        low, high = (int(index.min()), int(index.max())) if len(index) else (0, 0)
        if low < 0 or high >= n:
            return f"indices must lie in 0..{n - 1} (the scene's {n} Gaussians), got {low}..{high}"
        selected = len(index) > 0
    return None if selected else "selects no Gaussian: select at least one to restyle"


def stylise_start(original: GaussianScene, selected: torch.Tensor | None, degree: int) -> GaussianScene:
    """The scene stylisation starts from: at ``degree`` 0 the restyled Gaussians lose their SH rest bands
    (view-independent texture); above it the bands are kept (zero-padded up to ``degree``) and trained."""
    if degree == 0:
        return original.with_sh_degree(0) if selected is None else without_rest(original, selected)
    return original.with_sh_degree(degree if selected is None else max(degree, original.sh_degree))


def without_rest(scene: GaussianScene, rows: torch.Tensor) -> GaussianScene:
    """The scene with the SH bands above 0 of ``rows`` zeroed (restyled Gaussians are view-independent)."""
    return replace(scene, sh_rest=torch.where(rows[:, None, None], torch.zeros_like(scene.sh_rest), scene.sh_rest))
