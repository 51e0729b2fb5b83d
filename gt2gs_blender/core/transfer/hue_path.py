"""The way a splat's hue may go in a run: from the laid-out texture's toward the capture's own, nowhere else. One
rule for the layout term (a hue off that way costs ``losses.HUE_WEIGHT`` x) and for *No New Hues* (a colour is put
back on it after every step)."""

from __future__ import annotations

import torch

from .tone import LUMA, chroma, luma


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


def onto_hue_path(colours: torch.Tensor, start: torch.Tensor, scene: torch.Tensor) -> torch.Tensor:
    """(N, 3) ``colours`` with their light (luma) kept and their hue moved to the nearest on the way from ``start``'s
    hue to ``scene``'s (all (N, 3) RGB): lighter or darker as the steps made them, in no hue of their own."""
    y = luma(colours)
    cr, cb = nearest_on_segment(chroma(colours), chroma(start), chroma(scene)).unbind(-1)
    red, blue = y + cr, y + cb
    green = (y - LUMA[0] * red - LUMA[2] * blue) / LUMA[1]
    return torch.stack([red, green, blue], -1)
