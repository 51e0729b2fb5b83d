"""The texture bank a run matches against: its angle count, depth ratio and on-disk cache folder."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import torch

from ..features.extractor import FeatureExtractor
from ..features.specs import FeatureSpec
from ..progress import Tracker
from .config import MAX_DEPTH_RATIO, TransferConfig
from .skips import angles_for, texture_anisotropy
from .texture_bank import TextureBank, build_texture_bank, exact_crop, feature_map_bank, group_depth_ratio
from .views import ViewSet

BANK_CELLS = 8
"""Feature cells kept per side from the centre of each rotated crop (the authors' 8 x 8)."""


def bank_crop(spec: FeatureSpec) -> int:
    """The side texture crops are capped at for ``spec``: the smallest whose kept cells read no padding
    (80 px for VGG-16 relu3_1-3, 64 px for VGG-19 relu2_1 + relu3_1), so they are the cells of the full
    crop (tested on the real weights) at a fraction of its cost."""
    return exact_crop(spec.stride, spec.cell_reach(), BANK_CELLS)


CACHE_ENV = "GT2GS_CACHE_DIR"
"""Environment variable naming the texture-bank cache folder when the config gives none."""


def cache_dir(config: TransferConfig) -> Path | None:
    """The bank cache folder: the config's, else $GT2GS_CACHE_DIR, else ~/.cache/gt2gs_blender/banks;
    None when ``bank_cache`` is off."""
    if not config.bank_cache:
        return None
    if config.cache_dir:
        return Path(config.cache_dir)
    if os.environ.get(CACHE_ENV):
        return Path(os.environ[CACHE_ENV])
    return Path.home() / ".cache" / "gt2gs_blender" / "banks"


def bank_angle_count(texture: np.ndarray, config: TransferConfig) -> int:
    """The bank's angle count: ``n_angles``, or with ``adaptive_angles`` fewer for a texture with
    no strong local orientation (:func:`.skips.angles_for`)."""
    if not config.adaptive_angles:
        return config.n_angles
    return angles_for(texture_anisotropy(texture), config.n_angles)


def bank_depth_ratio(views: ViewSet, config: TransferConfig) -> float:
    """The farthest over the nearest depth group's depth that the bank's scales follow: the configured
    one, or the views' (all at once, as their groups), at most MAX_DEPTH_RATIO and rounded to 0.01 so
    that near-identical view sets share a cached bank (a 0.4 % scale change at most)."""
    if config.depth_ratio > 0.0:
        return config.depth_ratio
    measured = group_depth_ratio(torch.stack(views.depths), torch.stack(views.alphas), config.n_scales)
    return round(min(measured, MAX_DEPTH_RATIO), 2)


def build_bank(
    texture: np.ndarray,
    extractor: FeatureExtractor,
    config: TransferConfig,
    device: torch.device,
    tracker: Tracker,
    depth_ratio: float,
) -> TextureBank:
    """The texture's feature bank at scale 1 (renders are halved before VGG, the texture is not), its
    depth groups' scales spanning ``depth_ratio`` (paper §3.2: the group's texture shrinks as Z_1/Z_k)."""

    def report(fraction: float) -> None:
        tracker.check_cancel()
        tracker.tell(int(fraction * 100), 100, "texture feature bank")

    n_angles = bank_angle_count(texture, config)
    return build_texture_bank(
        texture,
        lambda x: extractor(x, scale=1.0),
        extractor_id=f"{extractor.fingerprint}:s1",
        n_scales=config.n_scales,
        n_angles=n_angles,
        depth_ratio_range=(1.0, depth_ratio),
        texture_height=config.texture_height,
        cells=BANK_CELLS,
        max_crop=bank_crop(extractor.spec),
        cache_dir=cache_dir(config),
        device=device,
        progress=report,
        angle_offset=config.angle % (360.0 / n_angles),
    ).to(device)


def nnfm_bank(
    texture: np.ndarray, extractor: FeatureExtractor, config: TransferConfig, device: torch.device
) -> TextureBank:
    """The plain NNFM loss's bank (``gt2`` off): the texture's own feature map at scale 1."""
    return feature_map_bank(
        texture,
        lambda x: extractor(x, scale=1.0),
        extractor_id=f"{extractor.fingerprint}:s1",
        texture_height=config.texture_height,
        device=device,
    ).to(device)
