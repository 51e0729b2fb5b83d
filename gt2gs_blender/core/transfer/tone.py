"""Light and dark apart from hue: the one luminance every light-and-dark rule uses, and the colour differences
that hold the hue."""

from __future__ import annotations

import torch

LUMA = (0.2126, 0.7152, 0.0722)
"""Rec. 709 luminance weights: light and dark apart from hue (the layout loss, the preview's shading,
``preview_ssim``)."""


def luma(colours: torch.Tensor) -> torch.Tensor:
    """The luminance (...) of ``colours`` (..., 3) by ``LUMA``: the one conversion every light-and-dark rule uses."""
    return colours @ torch.tensor(LUMA, dtype=colours.dtype, device=colours.device)


def chroma(rgb: torch.Tensor) -> torch.Tensor:
    """(N, 2) colour differences R - Y and B - Y of (N, 3) RGB: its hue and saturation apart from its light."""
    y = luma(rgb)
    return torch.stack([rgb[:, 0] - y, rgb[:, 2] - y], -1)


def from_light_and_chroma(y: torch.Tensor, differences: torch.Tensor) -> torch.Tensor:
    """(N, 3) RGB of luma ``y`` (N,) and colour differences ``differences`` (N, 2): :func:`chroma`'s inverse."""
    red, blue = y + differences[:, 0], y + differences[:, 1]
    green = (y - LUMA[0] * red - LUMA[2] * blue) / LUMA[1]
    return torch.stack([red, green, blue], -1)
