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
from ..device import cpu_threads
from ..errors import GT2GSError
from ..features.extractor import FeatureExtractor, load_feature_extractor, mixed_precision_dtype
from ..progress import ProgressCallback, Tracker
from ..render import resolve_backend
from ..scene.gaussians import GaussianScene
from . import color_transfer
from .bank import build_bank, nnfm_bank
from .config import TransferConfig, keeps_scene, splits_first, splits_last
from .content import content_degree
from .detail import add_detail, split_for_detail
from .layout import (
    bright_images,
    lay_out,
    layout_images,
    layout_materials,
    layout_shading,
    scene_colour_mix,
    seen_images,
    shade_width,
)
from .metrics import COVERED, MEASURE_SIDE, MEASURE_STRIDE, preview_ssim
from .orientation_preview import first_view, show
from .plan import RunPlan, plan_run
from .region import assemble, structure_changed
from .shade import laid_exposure
from .skips import Plateau
from .stylise import COLOR_ATTACHMENT, OWN_COLOUR_ATTACHMENT, Styliser, StyliseStats, ViewTargets, order_and_link
from .texture_bank import TextureBank, compact_bank
from .views import ViewSet, render_views, view_targets

STAGE_WEIGHTS = {"prepare": 0.1, "bank": 0.15, "stylise": 0.65, "finish": 0.1}
"""Rough share of a run's time per stage, for the overall progress fraction and the ETA."""


@dataclass
class TransferResult:
    """A transfer's stylised scene and its report (timings, settings, metrics)."""

    scene: GaussianScene
    report: dict


def _preview(image: torch.Tensor) -> np.ndarray:
    return (image.detach().clamp(0, 1) * 255 + 0.5).to(torch.uint8).cpu().numpy()


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
            if phase != "correct":
                loss, image = styliser.stylise_step(densify, nnfm=phase == "nnfm")
                preview = _preview(image) if styliser.report.stylise_steps % config.preview_every == 1 else None
                watched = "texture loss" if config.lambda_style > 0 else "loss"
                message = f"stylise: {watched} {loss:.3f}, {len(styliser.scene):,} Gaussians"
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


def keeps_scene_tones(config: TransferConfig) -> bool:
    """Whether the finish leaves the result's colours as the optimisation made them: with the layout keeping the
    scene (Keep Scene above 0) the texture's palette is already laid on it, and the closing colour transfer would
    squeeze the capture's light and dark into the texture's spread (the guitar's black stand came out light wood:
    object SSIM 0.47 with it, 0.62 without, the texture match no worse)."""
    return config.layout and keeps_scene(config)


@dataclass
class Prepared:
    """What the ``prepare`` stage hands on: the plan, the working scene and rows it restyles, the shade the layout
    keeps, the feature network, each view's targets, what the layout did (None: no layout), the start as the
    orientation preview shows it (None: not measured), how many splats there were before the layout split them and,
    for *No New Hues*, each splat's own colour before the layout (None: not kept)."""

    plan: RunPlan
    work: GaussianScene
    region: torch.Tensor | None
    shade: torch.Tensor | None
    extractor: FeatureExtractor
    targets: list[ViewTargets]
    laid_out: dict | None
    start_view: np.ndarray | None
    n_unsplit: int
    own_colours: torch.Tensor | None = None


def _transfer(
    scene: GaussianScene,
    texture: np.ndarray | str | os.PathLike,
    views: Sequence[Camera] | int | None,
    config: TransferConfig,
    region: torch.Tensor | np.ndarray | None,
    tracker: Tracker,
) -> TransferResult:
    """The body of :func:`transfer`: plan the run, then prepare, build the bank, stylise and finish it."""
    torch.manual_seed(config.seed)
    tracker.begin("prepare")
    prepared = _prepare(plan_run(scene, texture, views, config, region))
    plan, config = prepared.plan, prepared.plan.config
    tracker.end()

    tracker.begin("bank")
    # the labelled bank serves GT² matching and the texture-match metric of every variant
    image, device = plan.texture, plan.device
    extractor = prepared.extractor
    labelled = (
        build_bank(image, extractor, config, device, tracker, config.depth_ratio)
        if config.gt2 or config.evaluate
        else None
    )
    bank = labelled if config.gt2 else nnfm_bank(image, extractor, config, device)
    matching = compact_bank(bank, config.dedup_threshold, config.match_channels)
    tracker.end()

    tracker.begin("stylise")
    frozen = None if prepared.region is None else ~prepared.region
    carried = {SHADE_ATTACHMENT: prepared.shade} if prepared.shade is not None else {}
    if prepared.own_colours is not None:
        carried[OWN_COLOUR_ATTACHMENT] = prepared.own_colours
    work, frozen, stats, attached = stylise(
        prepared.work, plan.used, prepared.targets, matching, extractor, config, tracker, frozen, carried
    )
    tracker.end()

    tracker.begin("finish")
    work, metrics = _finish(prepared, work, frozen, stats, attached, labelled)
    tracker.end()
    report = _report(plan, tracker, work, extractor, bank, metrics)
    report["stylise"] = {
        **asdict(stats),
        "n_gaussians_start": len(plan.original),
        "region": None if plan.selected is None else int(plan.selected.sum()),
    }
    report["skips"] = _skips(plan, bank, matching, prepared.laid_out, stats)
    tracker.tell(1, 1, "done")
    return TransferResult(scene=work.to("cpu"), report=report)


def _prepare(plan: RunPlan) -> Prepared:
    """The ``prepare`` stage: the scene's own light and shade, the feature network, the layout (split and laid out,
    as the preview shows it) and each view's targets."""
    config, frame, image = plan.config, plan.frame, plan.texture
    work, region = plan.work, plan.region
    # the scene's own light and shade, as the preview takes it
    laying = frame is not None and config.layout
    bright, parts = layout_materials(work, region, config) if laying else (None, None)
    # what of its own colour each part keeps, taken before the layout recolours the splats
    mix = scene_colour_mix(work, region, config) if laying else config.scene_colour
    shade = layout_shading(work, region, frame, config, image, mix, bright, parts) if laying else None
    imaged = laying and config.lambda_layout > 0  # what the layout term's images take
    lit = bright_images(work, plan.used, bright, config.backend) if imaged and bright is not None else None
    hues = seen_images(work, plan.used, parts, config.backend) if imaged and parts is not None else None
    if config.color_transfer and not laying:  # the layout lays its own colours on every restyled splat
        work = apply_color_transfer(work, plan.content, image, region, config.backend)
    extractor = load_feature_extractor(
        config.features,
        config.weights_path,
        plan.device,
        scale=config.feature_scale,
        autocast=mixed_precision_dtype(plan.device, config.mixed_precision),
    )
    n_work = len(work)
    laid_out = start_view = own = None
    exposure = 1.0
    if laying:
        if splits_first(config):
            work, region, shade = split_for_detail(work, region, shade, frame, config)
        own = work.base_colors.detach().clamp(0.0, 1.0) if config.hue_on_path else None
        work = lay_out(work, region, plan.content, image, frame, config, shade)
        if config.evaluate and not splits_last(config):
            # the run's start as the orientation preview shows it, kept for preview_ssim (no second layout)
            start = assemble(work, region, plan.start, plan.selected, plan.hidden, changed=True)
            start_view = first_view(plan, start, _side(plan.cameras[0]))
        exposure = 1.0 if shade is None else laid_exposure(shade, region)
        laid_out = {
            "projection": config.layout_projection,
            "repeat_world": frame.repeat,
            "splats": len(work),
            "split": len(work) - n_work,
            "exposure": exposure,  # Scene Brightness: below 1 a gain, above the power 1 / exposure
        }
    targets = view_targets(plan.used, work, extractor, config, config.backend)
    if laying and config.lambda_layout > 0:
        shaded, width = shade is not None, shade_width(frame, config)
        ideal = layout_images(
            plan.used, image, frame, config.angle, shaded, width, config.keep_scene, mix, exposure, lit, hues
        )
        targets = [replace(t, layout_image=i) for t, i in zip(targets, ideal)]
    return Prepared(plan, work, region, shade, extractor, targets, laid_out, start_view, n_work, own)


def _finish(
    prepared: Prepared,
    work: GaussianScene,
    frozen: torch.Tensor | None,
    stats: StyliseStats,
    attached: dict[str, torch.Tensor],
    labelled: TextureBank | None,
) -> tuple[GaussianScene, dict | None]:
    """The ``finish`` stage: the detail split when it comes last, the closing colour transfer, the result put back
    into the whole scene, and its metrics (None when not evaluating)."""
    plan, config = prepared.plan, prepared.plan.config
    restyled = None if frozen is None else ~frozen
    if splits_last(config):
        n_optimised = len(work)
        start_colours, shade = attached[COLOR_ATTACHMENT], attached.get(SHADE_ATTACHMENT)
        work, restyled = add_detail(
            work, start_colours, restyled, plan.content, plan.texture, plan.frame, config, shade
        )
        prepared.laid_out.update(splats=len(work), split=len(work) - n_optimised)
    if config.color_transfer and not keeps_scene_tones(config):
        stylised_views = render_views(work, plan.cameras, plan.background, config.backend)
        work = apply_color_transfer(work, stylised_views, plan.texture, restyled, config.backend)
    changed = structure_changed(stats) or len(work) != prepared.n_unsplit
    work = assemble(work, restyled, plan.start, plan.selected, plan.hidden, changed)
    if not config.evaluate or labelled is None:  # always built when evaluating
        return work, None
    metrics = _evaluate(work, plan, prepared.targets, labelled, prepared.extractor, config)
    shown = prepared.start_view
    if shown is None:
        shown = show(plan, size=_side(plan.cameras[0])).image
    metrics["preview_ssim"] = preview_ssim(work, shown, plan.cameras[0], plan.background, config.backend)
    return work, metrics


def _skips(plan: RunPlan, bank: TextureBank, matching: TextureBank, laid_out: dict | None, stats: StyliseStats) -> dict:
    """The report's ``skips``: what the run left out or cut short, and what the layout did."""
    return {
        "hidden": None if plan.hidden is None else int(plan.hidden.sum()),
        "sh_degree": [plan.original.sh_degree, content_degree(plan.original, plan.config)],
        "bank_angles": len(bank.angles),
        "bank_rows_matched": len(matching),
        "match_channels": None if matching.match_basis is None else int(matching.match_basis.shape[1]),
        "dropped_views": plan.dropped,
        "layout": laid_out,
        "plateau_skipped": dict(stats.plateau_skipped),
    }


@torch.no_grad()
def _evaluate(
    result: GaussianScene,
    plan: RunPlan,
    targets: list[ViewTargets],
    bank: TextureBank,
    extractor: FeatureExtractor,
    config: TransferConfig,
) -> dict:
    """The paper's metrics on the run's views (the content measures on every other one at ``MEASURE_SIDE``), and
    texture match of the colour-transferred start (the content images of the used views, over the background as the
    result is measured)."""
    from ..features.lpips import load_lpips
    from .metrics import covered_features, evaluate, texture_match

    content = plan.content
    bg, cams = content.background, content.cameras
    stylised = render_views(result, cams, bg, config.backend)
    try:
        lpips = load_lpips(_weights_folder(config.weights_path), device=bg.device)
    except GT2GSError:
        lpips = None  # LPIPS weights not found: the lpips fields are reported as None
    images = torch.stack([stylised.composited(v) for v in range(len(cams))])
    metrics = evaluate(
        images,
        torch.stack(stylised.depths),
        torch.stack(stylised.alphas),
        cams,
        _measured_views(result, plan, config),
        lpips=lpips,
        extractor=extractor,
        bank_features=bank.features,
    )
    # the metric's own covered cells and background (as for the result), whatever the texture loss used
    start_features = torch.cat(
        [covered_features(extractor, t.content_image, alpha) for t, alpha in zip(targets, plan.used.alphas)]
    )
    metrics["texture_match_start"] = texture_match(start_features, bank.features)
    return metrics


def _measured_views(
    result: GaussianScene, plan: RunPlan, config: TransferConfig
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The result's and the original's renders and the original's covered pixels from every ``MEASURE_STRIDE``-th
    of the run's views, scaled so their frame (the working ``resolution``) is ``MEASURE_SIDE``: what the content
    measures read. SSIM's window spans less of the object at a larger size and a run's splats are shaped for its own,
    so content measured at each run's working size would not compare across Resolution, presets and Dense Upscale
    (the guitar read 0.745 at 480 px against 0.784 at 256, while held-out views at 512 px said the 480 px run kept
    more: 0.791 against 0.749)."""
    cameras = [cam.scaled(MEASURE_SIDE / plan.config.resolution) for cam in plan.cameras[::MEASURE_STRIDE]]
    degree = content_degree(plan.original, config)
    original = render_views(plan.original, cameras, plan.background, config.backend, degree)
    stylised = render_views(result, cameras, plan.background, config.backend)
    views = range(len(cameras))
    return (
        torch.stack([stylised.composited(v) for v in views]),
        torch.stack([original.composited(v) for v in views]),
        torch.stack(original.alphas) > COVERED,
    )


def _side(camera: Camera) -> int:
    """A view's longest side, in pixels."""
    return max(camera.width, camera.height)


def _weights_folder(path: str | None) -> str | None:
    """The folder to look for the LPIPS weights in: the configured weights folder (or a file's folder)."""
    if path is None:
        return None
    return path if os.path.isdir(path) else os.path.dirname(path) or None


def _report(
    plan: RunPlan,
    tracker: Tracker,
    scene: GaussianScene,
    extractor: FeatureExtractor,
    bank: TextureBank,
    metrics: dict | None,
) -> dict:
    """The run's report: timings, sizes, the device, rasterizer and network, the metrics, and the settings as asked
    (``asked``) and as run (``config``, every automatic value resolved; ``resolved`` lists those)."""
    cameras = plan.cameras
    return {
        "seconds": time.perf_counter() - tracker.start,
        "stage_seconds": dict(tracker.seconds),
        "n_gaussians": len(scene),
        "n_views": len(cameras),
        "image_size": [cameras[0].width, cameras[0].height],
        "device": str(plan.device),
        "rasterizer": resolve_backend(plan.config.backend, plan.device),
        "weights": dict(extractor.info),
        "bank": {"features": len(bank), "scales": list(bank.scales), "angles": len(bank.angles)},
        "metrics": metrics,
        "asked": plan.asked.to_dict(),
        "resolved": plan.resolved(),
        "config": plan.config.to_dict(),
    }
