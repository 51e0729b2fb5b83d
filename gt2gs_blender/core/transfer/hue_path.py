"""The way a splat's hue may go in a run: from the laid-out texture's toward the capture's own, nowhere else. One
rule for the layout term (a hue off that way costs ``losses.HUE_WEIGHT`` x) and for *No New Hues* (a push off it is
taken out of every step's gradient, and a colour is put back on it after the step)."""

from __future__ import annotations

import torch

from .tone import chroma, from_light_and_chroma, luma


def nearest_on_segment(point: torch.Tensor, start: torch.Tensor, end: torch.Tensor) -> torch.Tensor:
    """(N, 2) the point of each segment ``start`` -> ``end`` (N, 2) nearest ``point`` (N, 2); a segment of length
    zero is its start."""
    step = end - start
    length2 = (step * step).sum(-1)
    along = ((point - start) * step).sum(-1) / length2.clamp_min(torch.finfo(point.dtype).tiny)
    return start + along.clamp(0.0, 1.0)[:, None] * step


def off_path(point: torch.Tensor, start: torch.Tensor, end: torch.Tensor) -> torch.Tensor:
    """(N,) L1 distance of each (N, 2) point from the nearest point of the segment start -> end."""
    return (point - nearest_on_segment(point, start, end)).abs().sum(-1)


AT_AN_END = 1e-4
"""How near an end of the way (a fraction of its length) a hue counts as at that end."""


def onto_hue_path(colours: torch.Tensor, start: torch.Tensor, scene: torch.Tensor) -> torch.Tensor:
    """(N, 3) ``colours`` with their light (luma) kept and their hue moved to the nearest on the way from ``start``'s
    hue to ``scene``'s (all (N, 3) RGB): lighter or darker as the steps made them, in no hue of their own."""
    return from_light_and_chroma(luma(colours), nearest_on_segment(chroma(colours), chroma(start), chroma(scene)))


def along_hue_path(grad: torch.Tensor, colours: torch.Tensor, start: torch.Tensor, scene: torch.Tensor) -> torch.Tensor:
    """(N, 3) the colour gradient ``grad`` with its push off the way from ``start``'s hue to ``scene``'s taken out,
    for ``colours`` on that way (all (N, 3) RGB). What is left is an even shift of R, G and B (lighter or darker, no
    hue) plus a move of the hue along the way, kept only where it does not lead past an end. A push off the way,
    left in, would come back every step and, its RGB step not even, change the light each time it is undone."""
    even = torch.full((3,), 3.0**-0.5, dtype=grad.dtype, device=grad.device)
    a, b = chroma(start), chroma(scene)
    way = b - a
    length2 = (way * way).sum(-1)
    tiny = torch.finfo(grad.dtype).tiny
    along = ((chroma(colours) - a) * way).sum(-1) / length2.clamp_min(tiny)
    lifted = from_light_and_chroma(torch.zeros_like(length2), way)
    lifted = lifted - (lifted @ even)[:, None] * even
    norm = lifted.norm(dim=-1, keepdim=True)
    tangent = torch.where(norm > tiny**0.5, lifted / norm.clamp_min(tiny), torch.zeros_like(lifted))
    on_way = (grad * tangent).sum(-1)
    past_start = (along <= AT_AN_END) & (on_way > 0)
    past_end = (along >= 1.0 - AT_AN_END) & (on_way < 0)
    on_way = torch.where(past_start | past_end, torch.zeros_like(on_way), on_way)
    return (grad @ even)[:, None] * even + on_way[:, None] * tangent
