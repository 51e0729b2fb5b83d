"""Accents: a capture's rare, vivid colours (a robot's glowing eyes, a donut's sprinkles, a logo), kept under the
laid-out texture beyond the trace *Scene Colour* keeps of every part (``keep_accents``).

A colour is an accent as far as it is vivid (CIE Lab chroma across ``VIVID``) and rare: the scene's splats, each
weighed by how much of a view it covers, hold less than ``COMMON`` of their weight near it (a Gaussian of ``NEAR``
Lab units over a and b). The robot's orange shell and the guitar's sunburst are vivid but common, so they take the
texture as the other parts do; the robot's cyan eyes and the glow they cast, and the donut's blue sprinkles, keep
most of their own colour. An accent keeps its hue only: its light and dark stay the shaded texture's, so the
texture's pattern runs on through it (a flat hue there interrupted the pattern, and the measure lost a donut's toy
bricks). One table over (a, b) per run (:class:`ColourShare`), so the splats, the layout term's images and the
preview follow one rule.

Parts (``keep_hues``): every splat also keeps its part's hue (the mean colour of the part ``find_parts`` puts it in)
against grey, a shift of the texture's own hue that adds no light or dark (a chromaticity offset, luminance 0), so the
texture keeps its palette and its pattern while the icing stays pinker than the dough and a guitar's amber top
yellower than its stand. One hue per part, so a splat's own colour noise does not speckle the texture, and measured
from grey, so a grey part keeps the texture's hue and no part takes one the capture lacks.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import torch

from ..scene.parts import srgb_to_lab
from .tone import luma

VIVID = (10.0, 25.0)
"""Lab chroma: no accent at or below the first (greys, browns, pastels), fully vivid from the second."""
NEAR = 12.0
"""Lab a, b units: colours about this close count as one (about five just-noticeable differences)."""
COMMON = 0.05
"""A colour with this share of the scene's weight near it is no accent; rarer ones are, the rarer the more."""
BIN = 2.0
EXTENT = 128.0
"""The table's cells (Lab a, b units) and its half-width: a and b of sRGB colours lie within it."""
CELLS = round(2 * EXTENT / BIN)
DARK_FLOOR = 0.02
"""Colours darker than this luminance count as this when their hue is taken apart from their light and dark."""


@dataclass(frozen=True)
class ColourShare:
    """How much of each of a scene's colours a run mixes under the texture: ``base`` (*Scene Colour*) for every
    colour, raised toward 1 by ``keep`` (*Keep Accents*) times how much of an accent the colour is."""

    base: float
    keep: float
    rarity: np.ndarray
    """(B, B) over Lab (a, b), in 0..1: 1 where the scene holds no weight near that colour."""
    hues: float = 0.0
    """*Keep Hues*: how much of each splat's part's hue against grey shifts the texture's under it."""

    def __call__(self, colours: torch.Tensor) -> torch.Tensor:
        """(N,) the share of each of ``colours`` (N, 3 sRGB in 0..1) that stays under the texture."""
        return self.base + self.raised(colours)

    def raised(self, colours: torch.Tensor) -> torch.Tensor:
        """(N,) how far each of ``colours`` (N, 3) is raised above ``base``: ``keep`` of the rest, as an accent."""
        accent = torch.from_numpy(self.accent(colours.detach().float().cpu().numpy()))
        return ((1.0 - self.base) * self.keep * accent).to(colours)

    def mixed(
        self, colours: torch.Tensor, shade: torch.Tensor, parts: torch.Tensor | None = None
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """For ``colours`` (N, 3 sRGB in 0..1) shaded ``shade`` (N,) under the texture, of parts whose mean colours
        are ``parts`` (N, 3; None: no part's hue): (N, 1) the share that stays, (N, 3) what ``base`` of each colour
        adds as it is, and (N, 3) the hue, which the texture's luminance scales: the accent's (its raise of the
        share, times the shade, over the colour's own luminance) and ``hues`` of the part's chromaticity less grey on
        the texture's share (:func:`hue_offset`). The mix keeps the luminance the texture alone gives it and takes
        the accent's hue and the part's."""
        share = self(colours)[:, None]
        hue = (share - self.base) * chromaticity(colours)
        if parts is not None and self.hues > 0:
            hue = hue + self.hues * (1.0 - share) * hue_offset(parts.to(colours))
        return share, self.base * colours, shade[:, None] * hue

    def accent(self, colours: np.ndarray) -> np.ndarray:
        """(N,) how much of an accent each of ``colours`` (N, 3 sRGB in 0..1) is: vivid times rare."""
        lab = srgb_to_lab(np.clip(colours, 0.0, 1.0))
        chroma = np.hypot(lab[:, 1], lab[:, 2])
        vivid = np.clip((chroma - VIVID[0]) / (VIVID[1] - VIVID[0]), 0.0, 1.0)
        return (vivid * self.rarity[_cell(lab[:, 1]), _cell(lab[:, 2])]).astype(np.float32)


def colour_share(
    colours: torch.Tensor, weights: torch.Tensor, base: float, keep: float, hues: float = 0.0
) -> float | ColourShare:
    """What of the scene's own colour a run keeps under the texture: ``base`` alone when ``keep`` and ``hues`` are 0
    (or the scene has no weight), else a :class:`ColourShare` whose rarity comes from ``colours`` (N, 3 sRGB in
    0..1) weighed by ``weights`` (N,)."""
    w = weights.detach().double().cpu().numpy().clip(0.0, None)
    if (keep <= 0.0 and hues <= 0.0) or not len(w) or float(w.sum()) <= 0.0:
        return base
    rgb = colours.detach().double().cpu().numpy().clip(0.0, 1.0)
    lab = srgb_to_lab(rgb)
    share = np.zeros((CELLS, CELLS))
    np.add.at(share, (_cell(lab[:, 1]), _cell(lab[:, 2])), w / w.sum())
    sigma = NEAR / BIN
    near = cv2.GaussianBlur(share, (0, 0), sigma, borderType=cv2.BORDER_CONSTANT) * (2.0 * np.pi * sigma**2)
    rarity = np.clip(1.0 - near / COMMON, 0.0, 1.0)
    return ColourShare(base, keep, rarity, hues)


def chromaticity(colours: torch.Tensor) -> torch.Tensor:
    """(N, 3) ``colours`` (N, 3) over their luminance (at least ``DARK_FLOOR``): their hue apart from light and dark."""
    return colours / luma(colours).clamp_min(DARK_FLOOR)[:, None]


def hue_offset(colours: torch.Tensor) -> torch.Tensor:
    """(N, 3) the chromaticity of ``colours`` (N, 3) less grey's: luminance 0, so it shifts a hue and nothing else."""
    return chromaticity(colours) - 1.0


def _cell(values: np.ndarray) -> np.ndarray:
    """The table's cell index of Lab a or b ``values``."""
    return np.clip(((values + EXTENT) / BIN).astype(np.int64), 0, CELLS - 1)
