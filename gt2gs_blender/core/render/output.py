"""What a render returns, whichever backend made it."""

from __future__ import annotations

from dataclasses import dataclass

import torch

from .projection import Footprints


@dataclass
class RenderOutput:
    """Renders of B cameras. ``footprints`` holds the visible (camera, Gaussian) entries with their
    differentiable 2D means and extents (for densification statistics), from every backend."""

    colors: torch.Tensor  # (B, H, W, D) composited over the background
    depths: torch.Tensor | None  # (B, H, W) expected depth sum T*alpha*z (not divided by alpha)
    alphas: torch.Tensor  # (B, H, W)
    backend: str
    footprints: Footprints
