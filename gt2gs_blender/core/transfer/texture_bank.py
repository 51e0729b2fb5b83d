"""The texture feature bank of GT²-GS: texture features at K scales x n rotations, each labelled (k, theta).

Scales and depth groups (paper §3.2: "the scaling factor for each group is the ratio between the
lowest group depth Z_1 and the group's depth Z_k"):
- The rendered depth of the original scene is split into K equal bins (``depth_groups``); group 0
  holds the NEAREST surfaces, group K-1 the farthest.
- Bank scale index k serves depth group k: the texture is resized to height
  ``texture_height * scales[k]`` with ``scales[k] = Z_1 / Z_k = 1 / ratios[k]`` and
  ``ratios = linspace(*depth_ratio_range, K)``. The nearest group sees the texture largest (scale 1),
  far groups see it smaller, as perspective shows it. A run passes the views' own ratio of the
  farthest to the nearest bin centre (``group_depth_ratio``), so a surface gets one texture size in
  the world whichever group a view puts it in; the authors' code always uses 1..2 (heights 256,
  ~192, ~154, 128 for K = 4), which on a shallow object seen from around it (the donut: 1.44) shows
  the far side's texture too small, and differently sized from the near side's in the opposite view.

Rotations: ``theta`` is the angle, in degrees, by which the texture appears rotated
COUNTER-CLOCKWISE on screen (image y down), i.e. ``cv2.getRotationMatrix2D(centre, theta, 1)``;
in pixel coordinates (x right, y down) a texture direction v becomes ``[[c, s], [-s, c]] v``. Each
rotated texture is resampled into a centred square crop of side ``min(h, w)/sqrt(2)`` (no border
can show; Lanczos, reflected edge for the filter taps), rounded down to a multiple of 16 so the
centre feature cells sit exactly on the rotation centre, and optionally cut down to ``max_crop``.
Unlike the authors' code the crop is NOT resized back up, so the texture keeps its group's scale.

From each crop the extractor's centre ``cells x cells`` feature cells are kept, unit-normalised
over channels: ``K * n_angles * cells^2`` features in (k, theta, row, col) order.

Banks are cached as .npz files keyed by the decoded texture, every setting and the extractor id.
:func:`feature_map_bank` is the NNFM baseline's bank instead: the texture's feature map as it is.
"""

from __future__ import annotations

import hashlib
import io
import itertools
import json
import logging
import math
import os
import zipfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np
import torch
import torch.nn.functional as F

from ..atomic import atomic_write
from ..errors import GT2GSError

log = logging.getLogger(__name__)

Extractor = Callable[[torch.Tensor], torch.Tensor]
"""(B,3,H,W) RGB in [0,1] -> (B,C,h,w) features."""

MIN_CROP = 64
"""A scaled texture whose crop would be smaller than this (or than the cap) is tiled up to it: 8 cells
plus the network's context (schema 2; schema 1 reflected the border and refused tiny textures)."""

CACHE_SCHEMA = 2
"""Bumped whenever the bank's content for the same settings changes; old cache files then miss."""

CROP_MULTIPLE = 16
"""Crop sides are multiples of this, so features of strides up to 8 are centred on the rotation centre."""


@dataclass(frozen=True, eq=False)
class TextureBank:
    """M texture features with their labels. ``features`` (M,C) float32 unit rows; ``k`` (M,) int64
    scale index = depth group; ``theta`` (M,) float32 degrees; ``scales[k]`` the texture size factor
    of group k (1 = ``texture_height``); ``angles`` the rotations used; ``extractor_id`` names the
    feature extractor the features come from (they only compare with features from it)."""

    features: torch.Tensor
    k: torch.Tensor
    theta: torch.Tensor
    scales: tuple[float, ...]
    angles: tuple[float, ...]
    cells: int
    extractor_id: str
    match_basis: torch.Tensor | None = None  # (C, d) projection for matching (PCA), None = full channels
    match_features: torch.Tensor | None = None  # (M, d) unit rows of features @ match_basis

    def __len__(self) -> int:
        return int(self.features.shape[0])

    def to(self, device: torch.device | str) -> TextureBank:
        """The bank with its tensors on ``device``."""

        def move(t: torch.Tensor | None) -> torch.Tensor | None:
            return None if t is None else t.to(device)

        return replace(
            self,
            features=self.features.to(device),
            k=self.k.to(device),
            theta=self.theta.to(device),
            match_basis=move(self.match_basis),
            match_features=move(self.match_features),
        )


def compact_bank(bank: TextureBank, dedup_threshold: float = 0.0, pca_channels: int = 0) -> TextureBank:
    """The bank for matching: rows with a near-twin (cosine above ``dedup_threshold``, > 0) earlier
    in the same depth group dropped (labels kept, so rows need no longer come in equal runs per
    angle), and with ``pca_channels`` > 0 (fewer than C) the matching done on that many principal
    components (:func:`.skips.pca_basis`); the targets stay the full features."""
    from .skips import near_duplicates, pca_basis

    out = bank
    if dedup_threshold > 0.0:
        keep = ~near_duplicates(bank.features, bank.k, dedup_threshold)
        out = replace(
            bank,
            features=bank.features[keep],
            k=bank.k[keep],
            theta=bank.theta[keep],
            match_basis=None,
            match_features=None,
        )
    if 0 < pca_channels < out.features.shape[1]:
        basis = pca_basis(out.features, pca_channels)
        rows = F.normalize(F.normalize(out.features.float(), dim=1) @ basis, dim=1, eps=1e-8)
        out = replace(out, match_basis=basis, match_features=rows)
    return out


def bank_scales(n_scales: int, depth_ratio_range: tuple[float, float] = (1.0, 2.0)) -> tuple[float, ...]:
    """Texture size factor per depth group, nearest first: Z_1/Z_k for Z_k/Z_1 in linspace(range, K)."""
    lo, hi = depth_ratio_range
    if n_scales < 1 or not 0.0 < lo <= hi:
        raise ValueError(f"need n_scales >= 1 and 0 < ratio range low <= high, got {n_scales}, {depth_ratio_range}")
    return tuple(float(1.0 / r) for r in np.linspace(lo, hi, n_scales))


def build_texture_bank(
    texture: np.ndarray,
    extractor: Extractor,
    *,
    extractor_id: str,
    n_scales: int = 4,
    n_angles: int = 360,
    depth_ratio_range: tuple[float, float] = (1.0, 2.0),
    texture_height: int = 256,
    cells: int = 8,
    max_crop: int | None = None,
    cache_dir: str | os.PathLike | None = None,
    device: torch.device | str | None = None,
    batch_pixels: int = 2**19,
    progress: Callable[[float], None] | None = None,
    angle_offset: float = 0.0,
) -> TextureBank:
    """Build (or load from ``cache_dir``) the bank of ``texture`` (H,W,3) RGB float in [0,1].

    ``extractor`` is any callable (B,3,H,W) -> (B,C,h,w), given the crops at their own scale (an
    extractor that rescales renders must be called with its scale 1 here); it runs under no_grad on
    batches of at most ``batch_pixels`` input pixels, placed on ``device`` (default: the device of
    the extractor's parameters if it is a module, else the CPU). ``extractor_id`` must
    change whenever the extractor's weights or layers do (it keys the cache). ``progress`` gets the
    fraction done after each batch (raise from it to cancel). The angles are ``angle_offset + i *
    360 / n_angles`` (so a start angle off the grid can be on it), ascending in [0, 360).

    ``max_crop`` caps the crop side (rounded down to a multiple of 16). The centre cells do not
    change while the cap covers them plus the extractor's receptive field (:func:`exact_crop`: 80 px
    for VGG-16 relu3_1-3, 64 px for VGG-19 relu2_1 + relu3_1, for 8 cells at stride 4); building then
    costs a fraction of the full crops' time.
    """
    if n_angles < 1 or cells < 1 or texture_height < 1:
        raise ValueError(f"need n_angles, cells and texture_height >= 1, got {n_angles}, {cells}, {texture_height}")
    if max_crop is not None and max_crop < CROP_MULTIPLE:
        raise ValueError(f"max_crop must be at least {CROP_MULTIPLE}, got {max_crop}")
    image = np.ascontiguousarray(texture, dtype=np.float32)
    if image.ndim != 3 or image.shape[2] != 3:
        raise ValueError(f"texture must be (H, W, 3), got {image.shape}")
    scales = bank_scales(n_scales, depth_ratio_range)
    angles = tuple(sorted((angle_offset + i * 360.0 / n_angles) % 360.0 for i in range(n_angles)))
    settings = {
        "scales": scales,
        "angles": angles,
        "texture_height": texture_height,
        "cells": cells,
        "max_crop": max_crop,
        "extractor_id": extractor_id,
        "schema": CACHE_SCHEMA,
    }
    path = None if cache_dir is None else Path(cache_dir) / f"bank-{_cache_key(image, settings)}.npz"
    cached = None if path is None or not path.is_file() else _load(path, settings)
    if cached is not None:
        return cached
    target = device or _device_of(extractor)
    per_scale = []
    for k, scale in enumerate(scales):
        resized = _resize_to_height(image, max(1, round(texture_height * scale)))
        report = (lambda done, k=k: progress((k + done) / len(scales))) if progress else (lambda done: None)
        per_scale.append(_rotated_features(resized, angles, max_crop, extractor, target, cells, batch_pixels, report))
    bank = _labelled(torch.cat(per_scale), settings)
    if path is not None:
        _save(path, bank, settings)
    return bank


def feature_map_bank(
    texture: np.ndarray,
    extractor: Extractor,
    *,
    extractor_id: str,
    texture_height: int = 256,
    device: torch.device | str | None = None,
) -> TextureBank:
    """The NNFM loss's style features (paper Eq. 1, ARF): every feature cell of the texture resized
    to ``texture_height``, unit-normalised, as it is: one scale, no rotation (k = 0, theta = 0).

    This is the baseline the GT² loss improves on: no geometric labels, so a view can only match the
    texture the way it lies in the photo. ``cells`` is 0 (the whole map, not a centre crop)."""
    if texture_height < 1:
        raise ValueError(f"need texture_height >= 1, got {texture_height}")
    image = np.ascontiguousarray(_resize_to_height(np.asarray(texture, dtype=np.float32), texture_height))
    x = torch.from_numpy(image).permute(2, 0, 1)[None].to(device or _device_of(extractor))
    with torch.no_grad():
        feats = extractor(x)[0]
    c = feats.shape[0]
    rows = F.normalize(feats.float().reshape(c, -1).T, dim=1, eps=1e-8).cpu()
    return TextureBank(
        features=rows,
        k=torch.zeros(len(rows), dtype=torch.long),
        theta=torch.zeros(len(rows)),
        scales=(1.0,),
        angles=(0.0,),
        cells=0,
        extractor_id=extractor_id,
    )


def _labelled(features: torch.Tensor, settings: dict) -> TextureBank:
    """The bank of features stored in (k, theta, row, col) order, with their labels."""
    scales, angles, cells = tuple(settings["scales"]), tuple(settings["angles"]), settings["cells"]
    per_crop = cells * cells
    return TextureBank(
        features=features,
        k=torch.arange(len(scales)).repeat_interleave(len(angles) * per_crop),
        theta=torch.tensor(angles, dtype=torch.float32).repeat_interleave(per_crop).repeat(len(scales)),
        scales=scales,
        angles=angles,
        cells=cells,
        extractor_id=settings["extractor_id"],
    )


def _cache_key(image: np.ndarray, settings: dict) -> str:
    """sha256 of the decoded texture (shape and float32 samples) and every setting."""
    digest = hashlib.sha256(json.dumps(settings, sort_keys=True).encode())
    digest.update(repr(image.shape).encode())
    digest.update(image.tobytes())
    return digest.hexdigest()[:40]


def _resize_to_height(image: np.ndarray, height: int) -> np.ndarray:
    """Aspect-preserving resize: area averaging when shrinking, Lanczos (clipped) when enlarging."""
    h, w = image.shape[:2]
    width = max(1, round(w * height / h))
    if (height, width) == (h, w):
        return image
    shrinking = height < h
    out = cv2.resize(image, (width, height), interpolation=cv2.INTER_AREA if shrinking else cv2.INTER_LANCZOS4)
    return out if shrinking else np.clip(out, 0.0, 1.0)


def crop_side(height: int, width: int, max_crop: int | None = None) -> int:
    """Side of the centred square that stays inside the image under any rotation about its centre,
    at most ``max_crop``, rounded down to a multiple of 16 (when at least 16)."""
    side = int(min(height, width) / math.sqrt(2.0))
    if max_crop is not None:
        side = min(side, max_crop)
    return side - side % CROP_MULTIPLE if side >= CROP_MULTIPLE else side


def exact_crop(stride: int, reach: tuple[int, int], cells: int) -> int:
    """The smallest crop side (a multiple of ``CROP_MULTIPLE``) whose centre ``cells`` x ``cells`` feature
    cells read only the crop's own pixels, for an extractor whose cell j reads pixels ``stride * j +
    reach[0]`` to ``stride * j + reach[1]`` (``FeatureSpec.cell_reach``): no kept cell sees the padding, so
    they equal the cells of the same patch inside any larger image."""
    if stride < 1 or cells < 1 or reach[0] > 0 or reach[1] < stride - 1:
        raise ValueError(f"need stride, cells >= 1 and a reach around the cell, got {stride}, {cells}, {reach}")
    side = CROP_MULTIPLE
    while True:
        top = (side // stride - cells) // 2
        if top >= 0 and stride * top + reach[0] >= 0 and stride * (top + cells - 1) + reach[1] <= side - 1:
            return side
        side += CROP_MULTIPLE


def tiled_for_crop(image: np.ndarray, side: int) -> np.ndarray:
    """``image`` repeated an odd number of times each way (its centre stays the centre) until a
    ``side`` px crop fits inside it under any rotation: a texture scaled small for a far depth group
    or a small object is still a repeating pattern, and its few pixels would give too few feature cells."""
    need = math.ceil(side * math.sqrt(2.0)) + 1
    reps = [1 + 2 * math.ceil(max(0, need - n) / (2 * n)) for n in image.shape[:2]]
    if reps == [1, 1]:
        return image
    return np.tile(image, (reps[0], reps[1], 1))


def screen_rotation(angle_deg: float) -> np.ndarray:
    """(2, 2) float64: image offsets (x right, y down) turned ``angle_deg`` counter-clockwise on screen, the
    one rotation convention of the bank's crops, the layout and the orientation preview (OpenCV's own)."""
    return cv2.getRotationMatrix2D((0.0, 0.0), angle_deg, 1.0)[:, :2]


def rotate_crop(image: np.ndarray, angle: float, side: int) -> np.ndarray:
    """The ``side`` x ``side`` centre of ``image`` rotated ``angle`` degrees counter-clockwise on screen."""
    h, w = image.shape[:2]
    centre_in = ((w - 1) / 2.0, (h - 1) / 2.0)
    matrix = cv2.getRotationMatrix2D(centre_in, angle, 1.0)  # screen_rotation about the image's centre
    matrix[:, 2] += (side - 1) / 2.0 - np.asarray(centre_in)
    out = cv2.warpAffine(image, matrix, (side, side), flags=cv2.INTER_LANCZOS4, borderMode=cv2.BORDER_REFLECT_101)
    return np.clip(out, 0.0, 1.0)


def _rotated_features(
    image: np.ndarray,
    angles: Sequence[float],
    max_crop: int | None,
    extractor: Extractor,
    device: torch.device | str,
    cells: int,
    batch_pixels: int,
    progress: Callable[[float], None],
) -> torch.Tensor:
    """Centre feature cells of every rotation of one scaled texture: (n_angles * cells^2, C).

    A capped crop is cut from the full one, so its pixels are exactly the full crop's (OpenCV
    quantises sampling positions differently for different output placements)."""
    limit = max_crop or MIN_CROP
    if crop_side(*image.shape[:2]) < limit:  # a small scale: repeat the pattern rather than lose cells
        image, max_crop = tiled_for_crop(image, limit), limit
    full = crop_side(*image.shape[:2])
    side = crop_side(*image.shape[:2], max_crop)
    margin = (full - side) // 2
    batch = max(1, batch_pixels // (side * side))
    out = []
    for start in range(0, len(angles), batch):
        crops = np.stack(
            [
                rotate_crop(image, a, full)[margin : margin + side, margin : margin + side]
                for a in angles[start : start + batch]
            ]
        )
        x = torch.from_numpy(crops).permute(0, 3, 1, 2).contiguous().to(device)
        with torch.no_grad():
            feats = extractor(x)
        out.append(_centre_cells(feats, cells, side).cpu())
        progress(min(len(angles), start + batch) / len(angles))
    return torch.cat(out)


def _centre_cells(feats: torch.Tensor, cells: int, side: int) -> torch.Tensor:
    """(B,C,h,w) -> the centre cells x cells, unit-normalised over C, as (B*cells^2, C) float32."""
    _, c, h, w = feats.shape
    if h < cells or w < cells:
        raise GT2GSError(
            f"the texture is too small for the feature bank: a {side}x{side} px crop gives {h}x{w} "
            f"feature cells, fewer than the {cells}x{cells} kept; use a larger texture_height or fewer cells"
        )
    top, left = (h - cells) // 2, (w - cells) // 2
    centre = feats[:, :, top : top + cells, left : left + cells].float()
    return F.normalize(centre.permute(0, 2, 3, 1).reshape(-1, c), dim=1, eps=1e-8)


def _device_of(extractor: Extractor) -> torch.device:
    """The device of the extractor's first parameter or buffer; CPU for plain functions."""
    if isinstance(extractor, torch.nn.Module):
        first = next(itertools.chain(extractor.parameters(), extractor.buffers()), None)
        if first is not None:
            return first.device
    return torch.device("cpu")


def _save(path: Path, bank: TextureBank, settings: dict) -> None:
    """Write the bank atomically; a cache that cannot be written only costs a rebuild next time."""
    buffer = io.BytesIO()
    np.savez(buffer, features=bank.features.numpy(), settings=np.array(json.dumps(settings, sort_keys=True)))
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write(path, buffer.getbuffer())
    except OSError as exc:
        log.warning("could not write the texture bank cache %s (%s)", path, exc)


def _load(path: Path, settings: dict) -> TextureBank | None:
    """The cached bank, or None (logged) when the file is unreadable or does not match the settings."""
    try:
        with np.load(path, allow_pickle=False) as data:
            stored = json.loads(str(data["settings"]))
            features = torch.from_numpy(data["features"].copy())
        if stored != json.loads(json.dumps(settings, sort_keys=True)):
            raise ValueError("its settings differ")
        rows = len(settings["scales"]) * len(settings["angles"]) * settings["cells"] ** 2
        if features.dim() != 2 or len(features) != rows or features.dtype != torch.float32:
            raise ValueError(f"its features are not a ({rows}, C) float32 array")
        if not torch.isfinite(features).all():
            raise ValueError("its features are not finite")
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as exc:
        log.warning("ignoring the texture bank cache %s (%s); rebuilding it", path, exc)
        return None
    return _labelled(features, settings)


# ---------------------------------------------------------------------------------------------------
# Depth groups
# ---------------------------------------------------------------------------------------------------
def depth_groups(
    depth: torch.Tensor,
    alpha: torch.Tensor,
    n_groups: int,
    *,
    min_alpha: float = 0.5,
    depth_range: tuple[float, float] | None = None,
) -> torch.Tensor:
    """Depth group per pixel (…,H,W) int64: 0 = nearest … n_groups-1 = farthest, -1 = not covered.

    ``depth`` is the rasterizer's expected depth sum(T alpha z) and ``alpha`` its coverage; the
    surface depth is depth/alpha where alpha >= ``min_alpha``. The covered depths are min-max
    normalised (over all views passed at once, or over ``depth_range``) and split into
    ``n_groups`` equal bins. Group g uses bank scale index g (module notes). The authors normalise
    each view alone; passing all views together keeps a surface in the same group in every view.
    """
    if n_groups < 1:
        raise ValueError(f"n_groups must be at least 1, got {n_groups}")
    z, covered = _surface_depth(depth, alpha, min_alpha)
    if depth_range is None:
        if not covered.any():
            return torch.full(depth.shape, -1, dtype=torch.long, device=depth.device)
        lo, hi = float(z[covered].min()), float(z[covered].max())
    else:
        lo, hi = depth_range
    t = (z - lo) / (hi - lo) if hi > lo else torch.zeros_like(z)
    groups = (t * n_groups).floor().clamp(0, n_groups - 1).long()
    return torch.where(covered, groups, torch.full_like(groups, -1))


def group_depth_ratio(depth: torch.Tensor, alpha: torch.Tensor, n_groups: int, *, min_alpha: float = 0.5) -> float:
    """Z_K / Z_1 of :func:`depth_groups`' bins over the same covered pixels (bin centres): how many
    times smaller perspective shows a texture in the farthest group than in the nearest (paper §3.2's
    scale factors Z_1 / Z_k). 1.0 for one group or nothing covered."""
    z, covered = _surface_depth(depth, alpha, min_alpha)
    if n_groups < 2 or not covered.any():
        return 1.0
    lo, hi = float(z[covered].min()), float(z[covered].max())
    step = (hi - lo) / n_groups
    return (lo + (n_groups - 0.5) * step) / max(lo + 0.5 * step, 1e-12)


def _surface_depth(depth: torch.Tensor, alpha: torch.Tensor, min_alpha: float) -> tuple[torch.Tensor, torch.Tensor]:
    """The surface depth depth/alpha (0 elsewhere) and where alpha >= ``min_alpha`` covers the pixel."""
    covered = alpha >= min_alpha
    return torch.where(covered, depth / alpha.clamp_min(min_alpha), torch.zeros_like(depth)), covered


def pixel_cells(height: int, width: int, feature_hw: tuple[int, int], device: torch.device) -> torch.Tensor:
    """Index (H*W,) of the feature cell each pixel falls in, on an (h, w) grid over an (H, W) image."""
    h, w = feature_hw
    rows = torch.arange(height, device=device) * h // height
    cols = torch.arange(width, device=device) * w // width
    return (rows[:, None] * w + cols[None, :]).reshape(-1)


def covered_cells(
    alpha: torch.Tensor, feature_hw: tuple[int, int], min_alpha: float = 0.5, fraction: float = 0.5
) -> torch.Tensor:
    """Bool (…,h,w): feature cells more than ``fraction`` of whose pixels are covered (alpha >= ``min_alpha``;
    ``fraction`` 1: every pixel).

    The texture loss and texture match count only these: background cells cannot take the texture,
    and on a small object they would otherwise outnumber the object's cells."""
    *lead, height, width = alpha.shape
    h, w = feature_hw
    cell = pixel_cells(height, width, feature_hw, alpha.device)
    flat = (alpha >= min_alpha).reshape(-1, height * width).double()
    covered = torch.zeros(flat.shape[0], h * w, dtype=flat.dtype, device=alpha.device).index_add_(1, cell, flat)
    total = torch.bincount(cell, minlength=h * w).to(flat)
    whole = (covered >= total) & (total > 0)  # fraction 1 asks for this; a cell no pixel falls in is never covered
    return ((covered > fraction * total) | whole).reshape(*lead, h, w)


def cell_groups(groups: torch.Tensor, feature_hw: tuple[int, int]) -> torch.Tensor:
    """The pixel group map (…,H,W) on a feature grid (h, w): each cell takes the most frequent group
    among the pixels that fall in it (uncovered, -1, wins ties, then the nearer group; a cell no
    pixel falls in, when the grid is finer than the image, is -1)."""
    *lead, height, width = groups.shape
    h, w = feature_hw
    n_classes = int(groups.max()) + 2 if groups.numel() else 1
    cell = pixel_cells(height, width, feature_hw, groups.device)
    flat = groups.reshape(-1, height * width) + 1
    batch = torch.arange(flat.shape[0], device=groups.device)[:, None]
    index = (batch * (h * w) + cell[None, :]) * n_classes + flat
    counts = torch.bincount(index.reshape(-1), minlength=flat.shape[0] * h * w * n_classes)
    winner = counts.reshape(-1, h * w, n_classes).argmax(dim=-1) - 1
    return winner.reshape(*lead, h, w)
