"""The texture-transfer pipeline: scene + texture photo + views -> stylised scene + report.

Stages (each timed in the report): ``prepare`` (views, content renders of the original scene, colour
transfer, feature network), ``bank`` (the texture feature bank), ``stylise`` (optimise the Gaussians'
colours so their rendered features match the texture's, with content and TV terms), ``finish``
(colour transfer again, metrics). Progress goes to a callback with the stage, step, ETA and preview
frames; a cancel callable is polled between steps and raises ``Cancelled``.
"""
from __future__ import annotations

import contextlib
import hashlib
import os
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np
import torch

from . import color_transfer
from .cameras import Camera, auto_views
from .config import MAX_DEPTH_RATIO, TransferConfig
from .errors import GT2GSError
from .features import FeatureExtractor, load_feature_extractor, mixed_precision_dtype
from .gt2 import view_order
from .rasterizer import render
from .scene import GaussianScene, concat
from .skips import (
    Plateau,
    angles_for,
    redundant_views,
    texture_anisotropy,
    used_sh_degree,
)
from .stylise import (
    Styliser,
    StyliseStats,
    ViewTargets,
    frequency_levels,
    order_and_link,
)
from .texture import load_texture
from .texture_bank import (
    TextureBank,
    build_texture_bank,
    cell_groups,
    compact_bank,
    covered_cells,
    depth_groups,
    feature_map_bank,
    group_depth_ratio,
)

BANK_MAX_CROP = 64
"""Texture crops are capped at 64 px: the kept centre cells are then identical (tested), 3-4x faster."""
OBJECT_ALPHA = 0.9
"""Pixels above this alpha count as the object's own colour for the stylise backdrop."""
STAGE_WEIGHTS = {"prepare": 0.1, "bank": 0.15, "stylise": 0.65, "finish": 0.1}
"""Rough share of a run's time per stage, for the overall progress fraction and the ETA."""


class Cancelled(GT2GSError):
    """The run was cancelled by its caller; nothing was written."""


@dataclass
class Progress:
    """One progress report: ``fraction`` of the whole run done, ``eta_s`` seconds left (None at first)."""

    stage: str
    step: int
    total: int
    fraction: float
    eta_s: float | None
    message: str
    preview: np.ndarray | None = None  # (H,W,3) uint8 render of the first view, now and then


@dataclass
class TransferResult:
    scene: GaussianScene
    report: dict


@dataclass
class ViewSet:
    """The run's cameras and the original scene's renders from them (no gradients)."""

    cameras: list[Camera]
    premultiplied: list[torch.Tensor]  # (H,W,3) colour over black
    alphas: list[torch.Tensor]         # (H,W)
    depths: list[torch.Tensor]         # (H,W) expected depth sum(T alpha z)
    background: torch.Tensor           # (3,)

    def composited(self, v: int, background: torch.Tensor | None = None) -> torch.Tensor:
        """View ``v`` over ``background`` (3,) (None: the run's background)."""
        backdrop = self.background if background is None else background
        return self.premultiplied[v] + (1.0 - self.alphas[v][..., None]) * backdrop

    def object_colour(self, min_alpha: float = OBJECT_ALPHA) -> torch.Tensor:
        """Mean colour (3,) of the pixels the object covers (alpha above ``min_alpha``) in all views;
        the background colour when it covers none."""
        colours = [p[a > min_alpha] / a[a > min_alpha][:, None] for p, a in zip(self.premultiplied, self.alphas)]
        covered = torch.cat(colours) if colours else torch.zeros(0, 3)
        return covered.mean(0).clamp(0.0, 1.0) if len(covered) else self.background.clone()

    def subset(self, keep: Sequence[int]) -> ViewSet:
        """The views ``keep`` (indices, in that order)."""
        return ViewSet([self.cameras[v] for v in keep], [self.premultiplied[v] for v in keep],
                       [self.alphas[v] for v in keep], [self.depths[v] for v in keep], self.background)


@dataclass
class _Tracker:
    """Stage timing, progress fractions and cancellation for one run."""

    progress: Callable[[Progress], None] | None
    cancel: Callable[[], bool] | None
    start: float = field(default_factory=time.perf_counter)
    seconds: dict[str, float] = field(default_factory=dict)
    stage: str = "prepare"
    stage_start: float = field(default_factory=time.perf_counter)

    def begin(self, stage: str) -> None:
        self.check_cancel()
        self.stage, self.stage_start = stage, time.perf_counter()
        self.tell(0, 1, f"{stage}")

    def end(self) -> None:
        self.seconds[self.stage] = time.perf_counter() - self.stage_start

    def check_cancel(self) -> None:
        if self.cancel is not None and self.cancel():
            raise Cancelled("texture transfer cancelled")

    def tell(self, step: int, total: int, message: str, preview: np.ndarray | None = None) -> None:
        if self.progress is None:
            return
        done = sum(STAGE_WEIGHTS[s] for s in STAGE_WEIGHTS if s in self.seconds)
        fraction = min(1.0, done + STAGE_WEIGHTS[self.stage] * step / max(total, 1))
        elapsed = time.perf_counter() - self.start
        eta = elapsed * (1.0 - fraction) / fraction if fraction > 0.02 else None
        self.progress(Progress(self.stage, step, total, fraction, eta, message, preview))


def resolve_device(name: str) -> torch.device:
    """``auto`` = CUDA when present, else CPU; asking for CUDA without it is an error."""
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name == "cuda" and not torch.cuda.is_available():
        raise GT2GSError("device 'cuda' was asked for but torch sees no CUDA device; use --device cpu")
    return torch.device(name)


def fit_cameras(scene: GaussianScene, views: Sequence[Camera] | int | None, resolution: int,
                n_default: int) -> list[Camera]:
    """Automatic views (a count or None) or the given cameras resized so their longest side is ``resolution``."""
    if views is None or isinstance(views, int):
        return auto_views(scene, views or n_default, width=resolution, height=resolution)
    cameras = list(views)
    if not cameras:
        raise GT2GSError("no views given: pass cameras or a number of automatic views")
    return [cam.scaled(resolution / max(cam.width, cam.height)) for cam in cameras]


@torch.no_grad()
def render_views(scene: GaussianScene, cameras: Sequence[Camera], background: torch.Tensor,
                 backend: str, sh_degree: int | None = None) -> ViewSet:
    """Render every camera once (colour over black, alpha, depth), SH up to ``sh_degree`` (None = all)."""
    premultiplied, alphas, depths = [], [], []
    for cam in cameras:
        out = render(scene, [cam], backend=backend, sh_degree=sh_degree)
        premultiplied.append(out.colors[0])
        alphas.append(out.alphas[0])
        depths.append(out.depths[0])
    return ViewSet(list(cameras), premultiplied, alphas, depths, background)


def _to_nchw(image: torch.Tensor) -> torch.Tensor:
    return image.permute(2, 0, 1)[None]


def _preview(image: torch.Tensor) -> np.ndarray:
    return (image.detach().clamp(0, 1) * 255 + 0.5).to(torch.uint8).cpu().numpy()


def _load_texture(texture: np.ndarray | str | os.PathLike) -> np.ndarray:
    if isinstance(texture, np.ndarray):
        return np.ascontiguousarray(texture[..., :3], dtype=np.float32)
    return load_texture(texture)


CACHE_ENV = "GT2GS_CACHE_DIR"
"""Environment variable naming the texture-bank cache folder when the config gives none."""


def _cache_dir(config: TransferConfig) -> Path | None:
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


def apply_color_transfer(scene: GaussianScene, views: ViewSet, texture: np.ndarray,
                         rows: torch.Tensor | None = None, backend: str = "auto") -> GaussianScene:
    """ARF colour transfer fitted on the covered pixels of the views, applied exactly in SH space;
    with ``rows`` (a bool mask) fitted on the pixels those Gaussians cover and applied to them only."""
    weights = views.alphas
    if rows is not None:
        weights = render_views(scene.subset(rows), views.cameras, views.background, backend).alphas
    matrix, offset = color_transfer.fit_color_transform(views.premultiplied, texture, weights=weights)
    moved = color_transfer.apply_to_scene(scene, matrix, offset)
    if rows is None:
        return moved
    return replace(scene, sh_dc=torch.where(rows[:, None], moved.sh_dc, scene.sh_dc),
                   sh_rest=torch.where(rows[:, None, None], moved.sh_rest, scene.sh_rest))


def bank_depth_ratio(views: ViewSet, config: TransferConfig) -> float:
    """The farthest over the nearest depth group's depth that the bank's scales follow: the configured
    one, or the views' (all at once, as their groups), at most MAX_DEPTH_RATIO and rounded to 0.01 so
    that near-identical view sets share a cached bank (a 0.4 % scale change at most)."""
    if config.depth_ratio > 0.0:
        return config.depth_ratio
    measured = group_depth_ratio(torch.stack(views.depths), torch.stack(views.alphas), config.n_scales)
    return round(min(measured, MAX_DEPTH_RATIO), 2)


def build_bank(texture: np.ndarray, extractor: FeatureExtractor, config: TransferConfig, device: torch.device,
               tracker: _Tracker, depth_ratio: float) -> TextureBank:
    """The texture's feature bank at scale 1 (renders are halved before VGG, the texture is not), its
    depth groups' scales spanning ``depth_ratio`` (paper §3.2: the group's texture shrinks as Z_1/Z_k)."""

    def report(fraction: float) -> None:
        tracker.check_cancel()
        tracker.tell(int(fraction * 100), 100, "texture feature bank")

    n_angles = bank_angle_count(texture, config)
    return build_texture_bank(
        texture, lambda x: extractor(x, scale=1.0), extractor_id=f"{extractor.fingerprint}:s1",
        n_scales=config.n_scales, n_angles=n_angles, depth_ratio_range=(1.0, depth_ratio),
        texture_height=config.texture_height,
        max_crop=BANK_MAX_CROP, cache_dir=_cache_dir(config), device=device, progress=report,
        angle_offset=config.angle % (360.0 / n_angles),
    ).to(device)


def nnfm_bank(texture: np.ndarray, extractor: FeatureExtractor, config: TransferConfig,
              device: torch.device) -> TextureBank:
    """The plain NNFM loss's bank (``gt2`` off): the texture's own feature map at scale 1."""
    return feature_map_bank(texture, lambda x: extractor(x, scale=1.0), extractor_id=f"{extractor.fingerprint}:s1",
                            texture_height=config.texture_height, device=device).to(device)


@torch.no_grad()
def view_targets(views: ViewSet, start: GaussianScene, extractor: FeatureExtractor, config: TransferConfig,
                 backend: str) -> list[ViewTargets]:
    """Per view: the content image (the colour-transferred start's render), the backdrop the stylise
    phases render over and the content features over it, the covered cells, each cell's depth group
    and the AFCM frequency level (of the content image: an outline is detail to keep)."""
    start_views = render_views(start, views.cameras, views.background, backend)
    images = [start_views.composited(v) for v in range(len(views.cameras))]
    backdrop = start_views.object_colour() if config.object_backdrop else views.background
    feats = [extractor(_to_nchw(start_views.composited(v, backdrop))) for v in range(len(images))]
    masks = [covered_cells(views.alphas[v], tuple(feats[v].shape[-2:]), fraction=config.cell_coverage)
             for v in range(len(feats))]
    groups: list[torch.Tensor | None] = [None] * len(feats)
    if config.depth_groups and config.n_scales > 1:
        # all views at once, so a surface falls in the same depth group in every view
        pixel_groups = depth_groups(torch.stack(views.depths), torch.stack(views.alphas), config.n_scales)
        groups = [cell_groups(pixel_groups[v], tuple(feats[v].shape[-2:])) for v in range(len(feats))]
    levels = frequency_levels(images, masks)
    return [ViewTargets(cam, image, backdrop, f, m, g, level)
            for cam, image, f, m, g, level in zip(views.cameras, images, feats, masks, groups, levels)]


def stylise(scene: GaussianScene, views: ViewSet, targets: list[ViewTargets], bank: TextureBank,
            extractor: FeatureExtractor, config: TransferConfig, tracker: _Tracker,
            frozen: torch.Tensor | None) -> tuple[GaussianScene, torch.Tensor | None, StyliseStats]:
    """Run the stylise/correct schedule (module ``stylise``), reporting progress and previews; the
    scene, its frozen rows (after densification) and the counts."""
    order = order_and_link(targets, views.depths, views.alphas)
    styliser = Styliser(scene, targets, order, bank, extractor, config, views.background, frozen)
    phases = styliser.phases()
    total, step = sum(n for _, n, _ in phases), 0
    for phase, steps, densify in phases:
        plateau = Plateau(config.plateau_window, config.plateau_tol)
        for done in range(steps):
            tracker.check_cancel()
            if phase == "stylise":
                loss, image = styliser.stylise_step(densify)
                preview = _preview(image) if styliser.report.stylise_steps % config.preview_every == 1 else None
                message = f"stylise: texture loss {loss:.3f}, {len(styliser.scene):,} Gaussians"
            else:
                loss, preview = styliser.correct_step(), None
                message = f"preserve geometry: loss {loss:.4f}"
            step += 1
            tracker.tell(step, total, message, preview)
            if plateau.update(loss) and done + 1 < steps:
                styliser.report.plateau_skipped[phase] = styliser.report.plateau_skipped.get(phase, 0) \
                    + steps - done - 1
                step += steps - done - 1
                break
    return styliser.scene.detach(), None if frozen is None else styliser.opt.frozen.clone(), styliser.report


def transfer(
    scene: GaussianScene,
    texture: np.ndarray | str | os.PathLike,
    views: Sequence[Camera] | int | None = None,
    config: TransferConfig | None = None,
    *,
    region: torch.Tensor | np.ndarray | None = None,
    progress: Callable[[Progress], None] | None = None,
    cancel: Callable[[], bool] | None = None,
) -> TransferResult:
    """Re-texture ``scene`` with ``texture`` (a path or an (H,W,3) float array in [0,1]).

    ``views``: cameras, a number of automatic views, or None for the config's count. ``region``: a
    bool mask (N,) or an index array of the Gaussians to restyle; the others come out bit-identical,
    first and in their original order, followed by the restyled ones (and any densified). The input
    scene is not modified. The restyled Gaussians are view-independent (no SH bands above 0, as in
    the paper's code; ``config.stylised_sh_degree`` > 0 keeps and trains view-dependent bands); without
    a region the whole result has SH degree ``config.stylised_sh_degree``. Raises ``Cancelled``
    when ``cancel()`` returns True. ``config.threads`` > 0 sets the CPU thread count for the run.
    """
    config = config or TransferConfig()
    with cpu_threads(config.threads):
        return _transfer(scene, texture, views, config, region, _Tracker(progress, cancel))


@contextlib.contextmanager
def cpu_threads(count: int) -> Iterator[None]:
    """torch's (and so the C++ rasterizer's) intra-op thread count set to ``count`` for the block,
    then restored; 0 leaves torch's default (one per physical core)."""
    before = torch.get_num_threads()
    if count > 0:
        torch.set_num_threads(count)
    try:
        yield
    finally:
        if count > 0:
            torch.set_num_threads(before)


def _transfer(scene: GaussianScene, texture: np.ndarray | str | os.PathLike, views: Sequence[Camera] | int | None,
              config: TransferConfig, region: torch.Tensor | np.ndarray | None, tracker: "_Tracker") -> TransferResult:
    """The body of :func:`transfer`."""
    torch.manual_seed(config.seed)
    device = resolve_device(config.device)

    tracker.begin("prepare")
    image = _load_texture(texture)
    original = scene.detach().to(device)
    selected = region_mask(region, len(original), device)
    cameras = fit_cameras(original if selected is None else original.subset(selected), views, config.resolution,
                          config.n_views)
    background = torch.tensor(config.background, dtype=original.dtype, device=device)
    content, hidden = _content_and_hidden(original, cameras, background, config)
    start = work = _stylise_start(original, selected, config.stylised_sh_degree)
    if hidden is not None and selected is not None and not bool((selected & ~hidden).any()):
        hidden = None  # the whole region is hidden: restyle it as asked
    if hidden is not None:
        work = work.subset(~hidden)
    region = selected if selected is None or hidden is None else selected[~hidden]
    if config.color_transfer:
        work = apply_color_transfer(work, content, image, region, config.backend)
    extractor = load_feature_extractor(config.features, config.weights_path, device, scale=config.feature_scale,
                                       autocast=mixed_precision_dtype(device, config.mixed_precision))
    dropped = redundant_views(cameras, content.depths, content.alphas, view_order(cameras), config.min_new_coverage) \
        if config.drop_views and len(cameras) > 2 else []
    used = content.subset([v for v in range(len(cameras)) if v not in dropped]) if dropped else content
    targets = view_targets(used, work, extractor, config, config.backend)
    tracker.end()

    tracker.begin("bank")
    # the labelled bank serves GT² matching and the texture-match metric of every variant
    depth_ratio = bank_depth_ratio(used, config)
    labelled = build_bank(image, extractor, config, device, tracker, depth_ratio) \
        if config.gt2 or config.evaluate else None
    bank = labelled if config.gt2 else nnfm_bank(image, extractor, config, device)
    matching = compact_bank(bank, config.dedup_threshold, config.match_channels)
    tracker.end()

    tracker.begin("stylise")
    frozen = None if region is None else ~region
    work, frozen, stats = stylise(work, used, targets, matching, extractor, config, tracker, frozen)
    tracker.end()

    tracker.begin("finish")
    restyled = None if frozen is None else ~frozen
    if config.color_transfer:
        stylised_views = render_views(work, cameras, background, config.backend)
        work = apply_color_transfer(work, stylised_views, image, restyled, config.backend)
    work = _assemble(work, restyled, start, selected, hidden, _structure_changed(stats))
    metrics = None
    if config.evaluate and labelled is not None:  # always built when evaluating
        metrics = _evaluate(work, content, used, targets, labelled, extractor, config)
    tracker.end()
    report = _report(config, tracker, work, cameras, extractor, bank, metrics, device)
    report["stylise"] = {**asdict(stats), "n_gaussians_start": len(original),
                         "region": None if selected is None else int(selected.sum())}
    report["skips"] = {"hidden": None if hidden is None else int(hidden.sum()),
                       "sh_degree": [original.sh_degree, _content_degree(original, config)],
                       "bank_angles": len(bank.angles), "bank_rows_matched": len(matching),
                       "match_channels": None if matching.match_basis is None else int(matching.match_basis.shape[1]),
                       "dropped_views": dropped, "plateau_skipped": dict(stats.plateau_skipped)}
    tracker.tell(1, 1, "done")
    return TransferResult(scene=work.to("cpu"), report=report)


_CONTENT_CACHE: dict[str, tuple[ViewSet, torch.Tensor | None]] = {}
"""The last run's content renders and hidden set, by :func:`_content_key` (one entry: a re-run with
another texture, angle or schedule on the same scene and views reuses them)."""


def clear_caches() -> None:
    """Forget the in-process content cache (the disk bank cache stays)."""
    _CONTENT_CACHE.clear()


def _content_degree(scene: GaussianScene, config: TransferConfig) -> int:
    """SH degree the original is rendered at: the highest band in use with ``skip_sh``, else all."""
    return used_sh_degree(scene) if config.skip_sh else scene.sh_degree


def _content_key(scene: GaussianScene, cameras: Sequence[Camera], background: torch.Tensor,
                 config: TransferConfig) -> str:
    """sha256 of the scene's tensors, the cameras and every setting the content renders depend on."""
    digest = hashlib.sha256(repr((config.backend, config.skip_sh, config.skip_hidden, config.hidden_threshold,
                                  background.tolist(), str(scene.device), str(scene.dtype))).encode())
    for name, tensor in scene.tensors().items():
        digest.update(name.encode() + repr(tuple(tensor.shape)).encode())
        digest.update(tensor.detach().cpu().contiguous().numpy().tobytes())
    for cam in cameras:
        digest.update(repr((np.asarray(cam.world_to_cam).tolist(), cam.fx, cam.fy, cam.cx, cam.cy, cam.width,
                            cam.height)).encode())
    return digest.hexdigest()


def _content_and_hidden(original: GaussianScene, cameras: Sequence[Camera], background: torch.Tensor,
                        config: TransferConfig) -> tuple[ViewSet, torch.Tensor | None]:
    """The original's renders from the cameras and its hidden Gaussians (None when not skipped or
    none), from the in-process cache when ``reuse_content`` and the same scene and views ran last."""
    key = _content_key(original, cameras, background, config) if config.reuse_content else None
    if key is not None and key in _CONTENT_CACHE:
        return _CONTENT_CACHE[key]
    content = render_views(original, cameras, background, config.backend, _content_degree(original, config))
    hidden = hidden_gaussians(original, cameras, config.hidden_threshold, config.backend) \
        if config.skip_hidden else None
    if key is not None:
        _CONTENT_CACHE.clear()
        _CONTENT_CACHE[key] = (content, hidden)
    return content, hidden


HIDDEN_CAMERAS_PER_CALL = 4
"""Cameras rendered together when measuring each Gaussian's contribution."""


def contributions(scene: GaussianScene, cameras: Sequence[Camera], backend: str = "auto") -> torch.Tensor:
    """Per Gaussian (N,), its blending weight T*alpha summed over every pixel of every camera, in
    pixels: the gradient of the summed render of a zero colour probe, so exactly what compositing
    gives it (0 for a Gaussian culled, too faint or behind opaque ones everywhere)."""
    probe = torch.zeros(len(scene), 1, dtype=scene.dtype, device=scene.device, requires_grad=True)
    geometry = scene.detach()
    start = 0
    while start < len(cameras):
        size = (cameras[start].width, cameras[start].height)
        end = start + 1
        while end < len(cameras) and end - start < HIDDEN_CAMERAS_PER_CALL \
                and (cameras[end].width, cameras[end].height) == size:
            end += 1
        out = render(geometry, cameras[start:end], colors=probe, render_depth=False, backend=backend)
        out.colors.sum().backward()
        start = end
    return probe.grad[:, 0].detach() if probe.grad is not None else torch.zeros(len(scene), device=scene.device)


def hidden_gaussians(scene: GaussianScene, cameras: Sequence[Camera], threshold: float,
                     backend: str = "auto") -> torch.Tensor | None:
    """Bool (N,): the Gaussians whose summed contribution to the views is at most ``threshold``
    pixels (no view can show a change of theirs), or None when there are none (nothing to skip)."""
    hidden = contributions(scene, cameras, backend) <= threshold
    return hidden if bool(hidden.any()) and not bool(hidden.all()) else None


def _structure_changed(stats: StyliseStats) -> bool:
    """Whether densification added or removed any Gaussian during the run."""
    return any(d["cloned"] or d["split"] or d["pruned"] for d in stats.densified)


def _assemble(work: GaussianScene, restyled: torch.Tensor | None, start: GaussianScene,
              selected: torch.Tensor | None, hidden: torch.Tensor | None, changed: bool) -> GaussianScene:
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
    return concat(parts + [work.subset(restyled)])


def region_mask(region: torch.Tensor | np.ndarray | None, n: int, device: torch.device) -> torch.Tensor | None:
    """The region as a bool mask (n,) on ``device`` (from a mask or an index array); None = everything."""
    if region is None:
        return None
    region = torch.as_tensor(np.asarray(region) if not isinstance(region, torch.Tensor) else region)
    if region.dtype == torch.bool:
        if region.shape != (n,):
            raise GT2GSError(f"the region mask has {tuple(region.shape)} entries for a scene of {n} Gaussians")
        mask = region
    else:
        index = region.long().reshape(-1)
        if len(index) and (int(index.min()) < 0 or int(index.max()) >= n):
            raise GT2GSError(f"region indices must lie in [0, {n}), got {int(index.min())}..{int(index.max())}")
        mask = torch.zeros(n, dtype=torch.bool).index_fill_(0, index, True)
    if not bool(mask.any()):
        raise GT2GSError("the region is empty: select at least one Gaussian to restyle")
    return mask.to(device)


def _stylise_start(original: GaussianScene, selected: torch.Tensor | None, degree: int) -> GaussianScene:
    """The scene stylisation starts from: at ``degree`` 0 the restyled Gaussians lose their SH rest bands
    (view-independent texture); above it the bands are kept (zero-padded up to ``degree``) and trained."""
    if degree == 0:
        return original.with_sh_degree(0) if selected is None else _without_rest(original, selected)
    return original.with_sh_degree(degree if selected is None else max(degree, original.sh_degree))


def _without_rest(scene: GaussianScene, rows: torch.Tensor) -> GaussianScene:
    """The scene with the SH bands above 0 of ``rows`` zeroed (restyled Gaussians are view-independent)."""
    return replace(scene, sh_rest=torch.where(rows[:, None, None], torch.zeros_like(scene.sh_rest), scene.sh_rest))


@torch.no_grad()
def _evaluate(result: GaussianScene, content: ViewSet, used: ViewSet, targets: list[ViewTargets], bank: TextureBank,
              extractor: FeatureExtractor, config: TransferConfig) -> dict:
    """The paper's metrics on the run's views, and texture match of the colour-transferred start
    (the content images of the ``used`` views, over the background as the result is measured)."""
    from .lpips import load_lpips
    from .metrics import covered_features, evaluate, texture_match

    bg, cams = content.background, content.cameras
    stylised = render_views(result, cams, bg, config.backend)
    try:
        lpips = load_lpips(_weights_folder(config.weights_path), device=bg.device)
    except GT2GSError:
        lpips = None  # LPIPS weights not found: the lpips fields are reported as None
    images = torch.stack([stylised.composited(v) for v in range(len(cams))])
    originals = torch.stack([content.composited(v) for v in range(len(cams))])
    metrics = evaluate(images, originals, torch.stack(stylised.depths), torch.stack(stylised.alphas), cams,
                       lpips=lpips, extractor=extractor, bank_features=bank.features)
    # the metric's own covered cells and background (as for the result), whatever the texture loss used
    start_features = torch.cat([covered_features(extractor, t.content_image, alpha)
                                for t, alpha in zip(targets, used.alphas)])
    metrics["texture_match_start"] = texture_match(start_features, bank.features)
    return metrics


def _weights_folder(path: str | None) -> str | None:
    """The folder to look for the LPIPS weights in: the configured weights folder (or a file's folder)."""
    if path is None:
        return None
    return path if os.path.isdir(path) else os.path.dirname(path) or None


def _report(config: TransferConfig, tracker: _Tracker, scene: GaussianScene, cameras: Sequence[Camera],
            extractor: FeatureExtractor, bank: TextureBank, metrics: dict | None, device: torch.device) -> dict:
    return {
        "seconds": time.perf_counter() - tracker.start,
        "stage_seconds": dict(tracker.seconds),
        "n_gaussians": len(scene),
        "n_views": len(cameras),
        "image_size": [cameras[0].width, cameras[0].height],
        "device": str(device),
        "weights": dict(extractor.info),
        "bank": {"features": len(bank), "scales": list(bank.scales), "angles": len(bank.angles)},
        "metrics": metrics,
        "config": config.to_dict(),
    }
