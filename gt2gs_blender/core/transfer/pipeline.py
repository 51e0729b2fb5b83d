"""The texture-transfer pipeline: scene + texture photo + views -> stylised scene + report.

Stages (each timed in the report): ``prepare`` (views, content renders of the original scene, colour
transfer, feature network), ``bank`` (the texture feature bank), ``stylise`` (optimise the Gaussians'
colours so their rendered features match the texture's, with content and TV terms), ``finish``
(colour transfer again, metrics). Progress goes to a callback with the stage, step, ETA and preview
frames; a cancel callable is polled between steps and raises ``Cancelled``.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, replace

import numpy as np
import torch

from ..cameras.camera import Camera
from ..device import cpu_threads, resolve_device
from ..errors import GT2GSError
from ..features.extractor import FeatureExtractor, load_feature_extractor, mixed_precision_dtype
from ..progress import ProgressCallback, Tracker
from ..scene.gaussians import GaussianScene
from . import color_transfer
from .bank import bank_depth_ratio, build_bank, nnfm_bank
from .config import TransferConfig
from .content import content_and_hidden, content_degree
from .detail import add_detail, split_for_detail
from .gt2 import view_order
from .layout import lay_out, layout_frame, layout_images, layout_shading, shade_width, texture_height_for
from .metrics import preview_ssim
from .orientation_preview import preview
from .region import assemble, region_mask, structure_changed, stylise_start, visible_rows
from .skips import Plateau, redundant_views
from .stylise import COLOR_ATTACHMENT, Styliser, StyliseStats, ViewTargets, order_and_link
from .texture import load_texture
from .texture_bank import TextureBank, compact_bank
from .views import ViewSet, fit_cameras, render_views, view_targets

STAGE_WEIGHTS = {"prepare": 0.1, "bank": 0.15, "stylise": 0.65, "finish": 0.1}
"""Rough share of a run's time per stage, for the overall progress fraction and the ETA."""


@dataclass
class TransferResult:
    """A transfer's stylised scene and its report (timings, settings, metrics)."""

    scene: GaussianScene
    report: dict


def _preview(image: torch.Tensor) -> np.ndarray:
    return (image.detach().clamp(0, 1) * 255 + 0.5).to(torch.uint8).cpu().numpy()


def _load_texture(texture: np.ndarray | str | os.PathLike) -> np.ndarray:
    if isinstance(texture, np.ndarray):
        return np.ascontiguousarray(texture[..., :3], dtype=np.float32)
    return load_texture(texture)


def apply_color_transfer(
    scene: GaussianScene, views: ViewSet, texture: np.ndarray, rows: torch.Tensor | None = None, backend: str = "auto"
) -> GaussianScene:
    """ARF colour transfer fitted on the covered pixels of the views, applied exactly in SH space;
    with ``rows`` (a bool mask) fitted on the pixels those Gaussians cover and applied to them only."""
    weights = views.alphas
    if rows is not None:
        weights = render_views(scene.subset(rows), views.cameras, views.background, backend).alphas
    matrix, offset = color_transfer.fit_color_transform(views.premultiplied, texture, weights=weights)
    moved = color_transfer.apply_to_scene(scene, matrix, offset)
    if rows is None:
        return moved
    return replace(
        scene,
        sh_dc=torch.where(rows[:, None], moved.sh_dc, scene.sh_dc),
        sh_rest=torch.where(rows[:, None, None], moved.sh_rest, scene.sh_rest),
    )


SHADE_ATTACHMENT = "layout_shade"
"""The layout's per-splat shade, carried through densification to the detail split."""


def stylise(
    scene: GaussianScene,
    views: ViewSet,
    targets: list[ViewTargets],
    bank: TextureBank,
    extractor: FeatureExtractor,
    config: TransferConfig,
    tracker: Tracker,
    frozen: torch.Tensor | None,
    carried: dict[str, torch.Tensor] | None = None,
) -> tuple[GaussianScene, torch.Tensor | None, StyliseStats, dict[str, torch.Tensor]]:
    """Run the stylise/correct schedule (module ``stylise``), reporting progress and previews; the
    scene, its frozen rows (after densification), the counts and its per-row attachments after
    densification: each row's starting colour (``COLOR_ATTACHMENT``) and the ``carried`` values."""
    order = order_and_link(targets, views.depths, views.alphas)
    styliser = Styliser(scene, targets, order, bank, extractor, config, views.background, frozen, carried)
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
                styliser.report.plateau_skipped[phase] = (
                    styliser.report.plateau_skipped.get(phase, 0) + steps - done - 1
                )
                step += steps - done - 1
                break
    return (
        styliser.scene.detach(),
        None if frozen is None else styliser.opt.frozen.clone(),
        styliser.report,
        {name: value.detach() for name, value in styliser.opt.attachments.items()},
    )


def transfer(
    scene: GaussianScene,
    texture: np.ndarray | str | os.PathLike,
    views: Sequence[Camera] | int | None = None,
    config: TransferConfig | None = None,
    *,
    region: torch.Tensor | np.ndarray | None = None,
    progress: ProgressCallback | None = None,
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
        return _transfer(
            scene, texture, views, config, region, Tracker(progress, cancel, STAGE_WEIGHTS, "texture transfer")
        )


def _transfer(
    scene: GaussianScene,
    texture: np.ndarray | str | os.PathLike,
    views: Sequence[Camera] | int | None,
    config: TransferConfig,
    region: torch.Tensor | np.ndarray | None,
    tracker: Tracker,
) -> TransferResult:
    """The body of :func:`transfer`."""
    torch.manual_seed(config.seed)
    device = resolve_device(config.device)
    asked = config  # before the run derives its texture height: what the preview was made with

    tracker.begin("prepare")
    image = _load_texture(texture)
    original = scene.detach().to(device)
    selected = region_mask(region, len(original), device)
    cameras = fit_cameras(
        original if selected is None else original.subset(selected), views, config.resolution, config.n_views
    )
    background = torch.tensor(config.background, dtype=original.dtype, device=device)
    content, hidden = content_and_hidden(original, cameras, background, config)
    start = stylise_start(original, selected, config.stylised_sh_degree)
    hidden, region = visible_rows(selected, hidden)
    work = start if hidden is None else start.subset(~hidden)
    frame = None
    if config.layout or config.texture_repeats > 0:
        # sized on every selected splat, hidden ones too, as the orientation preview sizes it
        frame = layout_frame(original if selected is None else original.subset(selected), content, config)
    # the scene's own light and shade, before colour transfer changes it (as the preview takes it)
    shade = layout_shading(work, region, frame, config) if frame is not None and config.layout else None
    if config.color_transfer:
        work = apply_color_transfer(work, content, image, region, config.backend)
    extractor = load_feature_extractor(
        config.features,
        config.weights_path,
        device,
        scale=config.feature_scale,
        autocast=mixed_precision_dtype(device, config.mixed_precision),
    )
    dropped = (
        redundant_views(cameras, content.depths, content.alphas, view_order(cameras), config.min_new_coverage)
        if config.drop_views and len(cameras) > 2
        else []
    )
    used = content.subset([v for v in range(len(cameras)) if v not in dropped]) if dropped else content
    n_work = len(work)
    laid_out = None
    if frame is not None:
        if config.texture_repeats > 0:
            config = replace(config, texture_height=texture_height_for(frame, content, config.n_scales))
        if config.layout:
            if config.split_first and config.split_size > 0:
                work, region, shade = split_for_detail(work, region, shade, frame, config)
            work = lay_out(work, region, content, image, frame, config, shade)
            projection = "box" if frame.projector is None else "view"
            split = len(work) - n_work
            laid_out = {"projection": projection, "repeat_world": frame.repeat, "splats": len(work), "split": split}
    targets = view_targets(used, work, extractor, config, config.backend)
    if frame is not None and config.layout and config.lambda_layout > 0:
        ideal = layout_images(used, image, frame, config.angle, shade is not None, shade_width(frame, config))
        targets = [replace(t, layout_image=i) for t, i in zip(targets, ideal)]
    tracker.end()

    tracker.begin("bank")
    # the labelled bank serves GT² matching and the texture-match metric of every variant
    depth_ratio = bank_depth_ratio(used, config)
    labelled = (
        build_bank(image, extractor, config, device, tracker, depth_ratio) if config.gt2 or config.evaluate else None
    )
    bank = labelled if config.gt2 else nnfm_bank(image, extractor, config, device)
    matching = compact_bank(bank, config.dedup_threshold, config.match_channels)
    tracker.end()

    tracker.begin("stylise")
    frozen = None if region is None else ~region
    carried = None if shade is None else {SHADE_ATTACHMENT: shade}
    work, frozen, stats, attached = stylise(work, used, targets, matching, extractor, config, tracker, frozen, carried)
    tracker.end()

    tracker.begin("finish")
    restyled = None if frozen is None else ~frozen
    if config.layout and config.split_size > 0 and not config.split_first:
        n_optimised = len(work)
        start_colours, shade = attached[COLOR_ATTACHMENT], attached.get(SHADE_ATTACHMENT)
        work, restyled = add_detail(work, start_colours, restyled, content, image, frame, config, shade)
        laid_out.update(splats=len(work), split=len(work) - n_optimised)
    if config.color_transfer:
        stylised_views = render_views(work, cameras, background, config.backend)
        work = apply_color_transfer(work, stylised_views, image, restyled, config.backend)
    work = assemble(work, restyled, start, selected, hidden, structure_changed(stats) or len(work) != n_work)
    metrics = None
    if config.evaluate and labelled is not None:  # always built when evaluating
        metrics = _evaluate(work, content, used, targets, labelled, extractor, config)
        shown = preview(
            original, image, cameras, asked, size=max(cameras[0].width, cameras[0].height), region=selected
        ).image
        metrics["preview_ssim"] = preview_ssim(work, shown, cameras[0], background, config.backend)
    tracker.end()
    report = _report(config, tracker, work, cameras, extractor, bank, metrics, device)
    report["stylise"] = {
        **asdict(stats),
        "n_gaussians_start": len(original),
        "region": None if selected is None else int(selected.sum()),
    }
    report["skips"] = {
        "hidden": None if hidden is None else int(hidden.sum()),
        "sh_degree": [original.sh_degree, content_degree(original, config)],
        "bank_angles": len(bank.angles),
        "bank_rows_matched": len(matching),
        "match_channels": None if matching.match_basis is None else int(matching.match_basis.shape[1]),
        "dropped_views": dropped,
        "layout": laid_out,
        "plateau_skipped": dict(stats.plateau_skipped),
    }
    tracker.tell(1, 1, "done")
    return TransferResult(scene=work.to("cpu"), report=report)


@torch.no_grad()
def _evaluate(
    result: GaussianScene,
    content: ViewSet,
    used: ViewSet,
    targets: list[ViewTargets],
    bank: TextureBank,
    extractor: FeatureExtractor,
    config: TransferConfig,
) -> dict:
    """The paper's metrics on the run's views, and texture match of the colour-transferred start
    (the content images of the ``used`` views, over the background as the result is measured)."""
    from ..features.lpips import load_lpips
    from .metrics import covered_features, evaluate, texture_match

    bg, cams = content.background, content.cameras
    stylised = render_views(result, cams, bg, config.backend)
    try:
        lpips = load_lpips(_weights_folder(config.weights_path), device=bg.device)
    except GT2GSError:
        lpips = None  # LPIPS weights not found: the lpips fields are reported as None
    images = torch.stack([stylised.composited(v) for v in range(len(cams))])
    originals = torch.stack([content.composited(v) for v in range(len(cams))])
    metrics = evaluate(
        images,
        originals,
        torch.stack(stylised.depths),
        torch.stack(stylised.alphas),
        cams,
        lpips=lpips,
        extractor=extractor,
        bank_features=bank.features,
    )
    # the metric's own covered cells and background (as for the result), whatever the texture loss used
    start_features = torch.cat(
        [covered_features(extractor, t.content_image, alpha) for t, alpha in zip(targets, used.alphas)]
    )
    metrics["texture_match_start"] = texture_match(start_features, bank.features)
    return metrics


def _weights_folder(path: str | None) -> str | None:
    """The folder to look for the LPIPS weights in: the configured weights folder (or a file's folder)."""
    if path is None:
        return None
    return path if os.path.isdir(path) else os.path.dirname(path) or None


def _report(
    config: TransferConfig,
    tracker: Tracker,
    scene: GaussianScene,
    cameras: Sequence[Camera],
    extractor: FeatureExtractor,
    bank: TextureBank,
    metrics: dict | None,
    device: torch.device,
) -> dict:
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
