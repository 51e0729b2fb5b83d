"""The optimisation of a texture transfer: stylise phases (GT² loss, AFCM) alternating with the
Geometry Preservation Branch's correction phases, with densification early on (paper §3.2-3.4).

Stylise phase: the DC colours learn (with ``stylise_geometry`` on, as in the authors' code, the geometry
too, under the texture loss and the scale regulariser; ``auto`` turns it on for a capture seen from the
front, where the laid-out texture reaches near and far surfaces alike and only moved splats stop it
showing twice from the other views). Views are visited in the GT² order; each view's feature
cells get targets from the texture bank guided by the prior angles carried from the previous view
(the first view uses the start angle), weighted per cell by the AFCM map; plus content and TV terms.
With ``object_backdrop`` the stylise renders show the object over its own mean colour: over the
background, a cell on the outline matches a texture edge running along it, which the texture loss
then paints (a dark rim, a halo of splats) differently in every view.
Without GT² (``gt2`` off) the targets are plain NNFM's: the nearest cell of the texture's own feature map.
In the first half of the rounds the Gaussians whose DC-colour gradient is large are split, and the small ones
cloned where the stylise phases move splats (while only colours learn, a clone would sit on its parent for good);
a colour-only run on splats the layout has split to the texture's detail adds none (:func:`densifies`).
Correct phase: the Gaussians are rendered with the colours they had before stylisation (c^g) and
only their geometry learns, against the content images, with the 3DGS reconstruction loss (blind to
residuals under half a grey level, so geometry that already fits stays put) and the scale
regulariser (tolerating each Gaussian's starting elongation), so what densification and the texture
loss bent out of shape goes back. Where nothing did (a colour-only run: the splats neither move nor multiply), a
view the geometry fits stays fitted, so after its first draw its correct steps are taken without drawing it,
exactly as a drawn step with no gradient is (the donut's `fast` run: 134 of 150, 56 -> 32 s).
Gaussians outside the region never change (the optimiser's frozen rows).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import torch

from ..cameras.camera import Camera, camera_extent
from ..cameras.spread import cameras_from_front
from ..features.extractor import FeatureExtractor
from ..features.window import plain_features, windowed_features
from ..render import FixedGeometry, RenderOutput, fix_geometry, render
from ..scene.gaussians import GaussianScene
from ..scene.inria import SH_C0
from ..train.densify import DensifyConfig, DensityStats, densify_and_prune, densify_due
from ..train.optim import GaussianAdam, LearningRates
from ..train.reconstruction import reconstruction_loss
from .afcm import AFCMWeights, afcm_weight, depth_level, high_frequency_energy, normalise_frequency
from .config import FORWARD_SPREAD_DEG, PRUNE_SCREEN_RADIUS, PRUNE_WORLD_SCALE, TransferConfig, splits_first
from .gt2 import PriorLink, distortion, match_with_prior, prior_link, view_order
from .hue_path import along_hue_path, onto_hue_path
from .losses import anisotropy, content_loss, cosine_distance, layout_loss, light_only, scale_regulariser, tv_loss
from .texture_bank import TextureBank

GEOMETRY = ("means", "quats", "log_scales", "opacity_logits")
"""The tensors the correction phases train."""
COLOR_ATTACHMENT = "c_g"
CORRECT_TOLERANCE = 0.5 / 255
"""Residuals the correction phases leave alone: half an 8-bit grey level (see train.reconstruction)."""
REUSE_BUDGET = 1 << 30
"""Bytes of compositing weights kept across steps (~8 MiB per 256 px view of a 300k-splat donut); views
beyond it are redrawn from fresh weights every step (still cheaper than a full render's backward)."""
RATIO_ATTACHMENT = "ratio_limit"
"""Per Gaussian, the scale ratio the correction phases tolerate (children inherit their parent's)."""
OWN_COLOUR_ATTACHMENT = "own_colour"
"""Per Gaussian, its colour in the capture before the layout (children inherit their parent's): where *No New Hues*
lets its hue go back to."""


@dataclass
class ViewTargets:
    """What the stylise phases need of one view, fixed for the run: the content image (the colour-
    transferred original render, over the background), the backdrop (3,) stylise renders are made over
    and the content features over it, covered cells, depth groups, AFCM frequency level, and the prior
    link to the view visited before it (None for the first)."""

    camera: Camera
    content_image: torch.Tensor
    backdrop: torch.Tensor
    content_features: torch.Tensor
    mask: torch.Tensor
    groups: torch.Tensor | None
    frequency: torch.Tensor
    link: PriorLink | None = None
    layout_image: torch.Tensor | None = None
    """With the layout on: the laid-out texture as an ideal surface shows it (H, W, 4: colour, coverage)."""


@dataclass
class StyliseStats:
    """Counts for the report."""

    stylise_steps: int = 0
    correct_steps: int = 0
    skipped_steps: int = 0
    moved_splats: bool = False  # whether the stylise phases moved the geometry (Texture Moves Splats)
    densified: list[dict] = field(default_factory=list)
    plateau_skipped: dict[str, int] = field(default_factory=dict)  # steps left out at a loss plateau, per phase
    reused_weights: int = 0  # stylise steps drawn from compositing weights kept from an earlier step
    fitted_correct_steps: int = 0  # correct steps on a view the unmoved geometry already fits: stepped, not drawn
    feature_area: float = 1.0  # mean share of a stylise step's view the feature network ran on (Features Near Splats)


def moves_splats(cameras: list[Camera], choice: str) -> bool:
    """Whether the stylise phases move the splats: ``on``, ``off``, or ``auto``: for a capture seen from the
    front (``FORWARD_SPREAD_DEG``), not for an object seen from all sides, whose outline it would loosen."""
    return choice == "on" or (choice == "auto" and cameras_from_front(cameras, FORWARD_SPREAD_DEG))


def densifies(config: TransferConfig, moved_splats: bool) -> bool:
    """Whether the stylise phases add splats: with Densify on, unless only the colours learn on splats the layout
    has already split to the texture's detail. There a clone would sit on its parent for good, and 3DGS's split
    (children drawn at random from a long splat) reshapes the capture: the guitar kept 0.02-0.03 less of itself
    over its pixels, and no texture was found more."""
    return config.densify and (moved_splats or not splits_first(config))


def schedule(config: TransferConfig, moved_splats: bool) -> list[tuple[str, int, bool]]:
    """(phase, steps, densify) in run order: ``rounds`` x (stylise, correct), or with ``nnfm_half``
    ``rounds`` x (stylise, correct, nnfm, correct), each half with half the round's steps. Without the
    GPB the stylise phases join, densifying (:func:`densifies`, given whether the splats move) over the same first
    half of the rounds as with it, so that removing the GPB removes only the correction phases."""
    rounds = max(1, config.rounds)
    parts = 2 * rounds if config.nnfm_half else rounds
    grows = densifies(config, moved_splats)
    out: list[tuple[str, int, bool]] = []
    for p in range(parts):
        stylise = config.stylise_steps * (p + 1) // parts - config.stylise_steps * p // parts
        kind = "nnfm" if config.nnfm_half and p % 2 else "stylise"
        out.append((kind, stylise, grows and p * rounds // parts < math.ceil(rounds / 2)))
        if config.gpb:
            out.append(("correct", config.correct_steps * (p + 1) // parts - config.correct_steps * p // parts, False))
    joined: list[tuple[str, int, bool]] = []
    for phase in (p for p in out if p[1] > 0):
        if joined and joined[-1][0] == phase[0] and joined[-1][2] == phase[2]:
            joined[-1] = (phase[0], joined[-1][1] + phase[1], phase[2])
        else:
            joined.append(phase)
    return joined


def order_and_link(targets: list[ViewTargets], depths: list[torch.Tensor], alphas: list[torch.Tensor]) -> list[int]:
    """The GT² visiting order of the views; sets each visited view's prior link to its predecessor."""
    order = view_order([t.camera for t in targets])
    for previous, current in itertools.pairwise(order):
        t, p = targets[current], targets[previous]
        t.link = prior_link(
            t.camera,
            depths[current],
            alphas[current],
            p.camera,
            depths[previous],
            alphas[previous],
            tuple(t.mask.shape),
            tuple(p.mask.shape),
        )
    return order


def frequency_levels(images: list[torch.Tensor], masks: list[torch.Tensor]) -> list[torch.Tensor]:
    """AFCM's I_f of every view (normalised together)."""
    energies = [high_frequency_energy(image, tuple(mask.shape)) for image, mask in zip(images, masks)]
    return normalise_frequency(energies, masks)


class Styliser:
    """Runs the schedule of one transfer on ``scene`` (the colour-transferred working scene)."""

    def __init__(
        self,
        scene: GaussianScene,
        views: list[ViewTargets],
        order: list[int],
        bank: TextureBank,
        extractor: FeatureExtractor,
        config: TransferConfig,
        background: torch.Tensor,
        frozen: torch.Tensor | None = None,
        carried: dict[str, torch.Tensor] | None = None,
    ) -> None:
        """``carried``: per-splat values that must follow densification (the layout's shade), by name."""
        self.views, self.order, self.bank, self.extractor, self.config = views, order, bank, extractor, config
        self.background = background
        self.extent = camera_extent([v.camera for v in views]) if len(views) > 1 else 1.0
        self.colors = ("sh_dc", "sh_rest") if config.stylised_sh_degree > 0 else ("sh_dc",)
        self.opt = GaussianAdam(
            scene,
            self._lrs(),
            trainable=self.colors,
            frozen=frozen,
            shared_channels=self.colors if config.texture_keeps_hue or config.hue_on_path else (),
            attachments={
                COLOR_ATTACHMENT: scene.base_colors.detach(),
                RATIO_ATTACHMENT: self._ratio_limits(scene),
                **(carried or {}),
            },
        )
        self.report = StyliseStats(moved_splats=moves_splats([v.camera for v in views], config.stylise_geometry))
        self.densify_config = DensifyConfig(
            grad_threshold=config.densify_grad_threshold,
            grad_source="color",
            max_screen_radius=PRUNE_SCREEN_RADIUS,
            max_world_scale=PRUNE_WORLD_SCALE,
            clone=self.report.moved_splats,  # a clone moves apart from its parent only under the texture loss
        )
        self.stats = DensityStats(len(scene), "color", device=scene.device)
        self.max_gaussians = int(len(scene) * config.densify_max_growth)
        self.angle_maps: dict[int, torch.Tensor] = {}
        self.cursor = 0
        self.generator = torch.Generator().manual_seed(config.seed)
        self.kept: dict[int, FixedGeometry] = {}
        self.fitted: dict[int, float] = {}
        # the empty backdrop's features (Features Near Splats), one per view size and backdrop: views alike share them
        self.plain: dict[tuple[int, int, int], torch.Tensor] = {}

    def _ratio_limits(self, scene: GaussianScene) -> torch.Tensor:
        """(N,) scale ratio each Gaussian may keep: the configured limit, or its own starting ratio
        when larger and ``scale_ratio_from_start`` (a fitted scene's thin Gaussians are its geometry)."""
        limit = torch.full((len(scene),), float(self.config.scale_ratio_limit), dtype=scene.dtype, device=scene.device)
        if not self.config.scale_ratio_from_start:
            return limit
        return torch.maximum(limit, anisotropy(scene.log_scales.detach()))

    def _lrs(self) -> dict[str, float]:
        lrs = LearningRates().at(0, 1, self.extent)
        lrs["sh_dc"] = self.config.lr
        lrs["sh_rest"] = self.config.lr / 20.0  # 3DGS's ratio of the rest bands' rate to the DC's
        return lrs

    @property
    def scene(self) -> GaussianScene:
        return self.opt.scene

    # -- schedule ---------------------------------------------------------------------------------
    def phases(self) -> list[tuple[str, int, bool]]:
        """This run's :func:`schedule`."""
        return schedule(self.config, self.report.moved_splats)

    # -- stylise ----------------------------------------------------------------------------------
    def stylise_step(self, densify: bool, nnfm: bool = False) -> tuple[float, torch.Tensor]:
        """One GT² step on the next view in order (``nnfm``: a plain nearest-match step of an NNFM
        half-round); (the loss a plateau watches: the texture loss, or with Texture Strength 0 the step's whole
        loss, the layout fit; the rendered image over the background). Texture Strength 0 matches nothing."""
        cfg = self.config
        v = self.order[self.cursor]
        view = self.views[v]
        self.opt.set_trainable(self.colors + GEOMETRY if self.report.moved_splats else self.colors)
        out = self._stylise_render(v, view)
        image = out.colors[0]
        seen = light_only(image) if cfg.texture_keeps_hue else image
        feats, area = self._features(v, view, seen, out.alphas[0].detach())
        self.report.feature_area += (area - self.report.feature_area) / (self.report.stylise_steps + 1)
        style = self._texture_loss(feats[0], v, view, nnfm) if cfg.lambda_style > 0 else None
        loss = (
            (0.0 if style is None else cfg.lambda_style * style)
            + cfg.lambda_content * content_loss(feats, view.content_features)
            + cfg.lambda_tv * tv_loss(image[None])
        )
        if view.layout_image is not None:
            loss = loss + cfg.lambda_layout * layout_loss(image, view.layout_image, view.content_image)
        if self.report.moved_splats:
            loss = loss + cfg.lambda_scale * self._scale_term()
        loss.backward()
        if densify:
            self.stats.add(out.footprints, view.camera.width, view.camera.height, self.scene.sh_dc.grad)
        hue_on_path = cfg.hue_on_path and OWN_COLOUR_ATTACHMENT in self.opt.attachments
        if hue_on_path:
            self._push_along_hue_path()
        self._step(loss)
        if hue_on_path:
            self._hue_back_on_path()
        if self.report.moved_splats:
            self._geometry_moved()
        self.cursor = (self.cursor + 1) % len(self.order)
        self.report.stylise_steps += 1
        due = densify_due(self.report.stylise_steps, cfg.densify_every)
        if densify and due and len(self.scene) < self.max_gaussians:
            done = densify_and_prune(
                self.opt,
                self.stats,
                self.densify_config,
                self.extent,
                prune_large=cfg.prune_large,
                generator=self.generator,
            )
            if done.cloned or done.split or done.pruned:
                self._geometry_moved()
            self.report.densified.append(
                {
                    "step": self.report.stylise_steps,
                    "cloned": done.cloned,
                    "split": done.split,
                    "pruned": done.pruned,
                    "total": done.total,
                }
            )
        shown = image.detach() + (1.0 - out.alphas[0].detach()[..., None]) * (self.background - view.backdrop)
        return float((loss if style is None else style).detach()), shown

    def _stylise_render(self, v: int, view: ViewTargets) -> RenderOutput:
        """View ``v`` with the current colours. While the splats hold still (a colour-only step, and
        ``reuse_weights``), from the view's compositing weights, recorded once and kept until the geometry
        changes (within ``REUSE_BUDGET``); else a full render."""
        cfg = self.config
        full = not cfg.reuse_weights or self.report.moved_splats
        fixed = None if full else self.kept.get(v)
        if fixed is not None:
            self.report.reused_weights += 1
        elif not full:
            fixed = fix_geometry(self.scene, [view.camera], backend=cfg.backend)
            if fixed is not None and fixed.nbytes + sum(k.nbytes for k in self.kept.values()) <= REUSE_BUDGET:
                self.kept[v] = fixed
        if fixed is None:
            return render(self.scene, [view.camera], background=view.backdrop, backend=cfg.backend, render_depth=False)
        return fixed.render(self.scene, background=view.backdrop)

    def _features(
        self, v: int, view: ViewTargets, image: torch.Tensor, alpha: torch.Tensor
    ) -> tuple[torch.Tensor, float]:
        """VGG features of view ``v``'s render ``image`` (H,W,3) over its backdrop, and the share of the view the
        network ran on: with *Features Near Splats* only near the splats (``alpha`` > 0, H,W), the empty backdrop's
        features filling the rest."""
        images = image.permute(2, 0, 1)[None]
        if not self.config.feature_window:
            return self.extractor(images), 1.0

        def plain() -> torch.Tensor:
            # the backdrop by identity: view_targets gives a run's views one tensor, and reading its values
            # would wait for the GPU at every step
            key = (image.shape[0], image.shape[1], id(view.backdrop))
            if key not in self.plain:
                self.plain[key] = plain_features(self.extractor, image.shape[0], image.shape[1], view.backdrop)
            return self.plain[key]

        return windowed_features(self.extractor, images, alpha, plain)

    def _texture_loss(self, feats: torch.Tensor, v: int, view: ViewTargets, nnfm: bool) -> torch.Tensor:
        """The texture loss of view ``v``: the AFCM-weighted distance to the matched targets over its covered
        cells (:meth:`_texture_terms`)."""
        distances, weights = self._texture_terms(feats, v, view, nnfm)
        counted = view.mask
        return (weights * distances)[counted].mean() if counted.any() else distances.sum() * 0.0

    def _texture_terms(
        self, feats: torch.Tensor, v: int, view: ViewTargets, nnfm: bool = False
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Per-cell cosine distance to the targets (with gradients) and the AFCM weight (h,w). An NNFM
        half-round step (``nnfm``) matches without the prior, weighs every cell alike and leaves the
        angles the GT² steps carry from view to view as they were."""
        cfg = self.config
        guided = cfg.gt2 and not nnfm
        prior = self._prior(v, view) if guided else self._unknown_angles(view)
        # NNFM's bank is one unlabelled feature map: every cell matches all of it, whatever its depth group
        match = match_with_prior(
            feats.detach(),
            self.bank,
            prior,
            cfg.lambda_prior if guided else 0.0,
            view.groups if cfg.gt2 else None,
            view.mask,
        )
        if guided:
            self.angle_maps[v] = torch.where(view.mask, match.angles, torch.full_like(match.angles, math.nan))
        c = feats.shape[0]
        targets = self.bank.features[match.indices.reshape(-1)].to(feats)
        distances = cosine_distance(feats.reshape(c, -1).T, targets).reshape(view.mask.shape)
        if not cfg.afcm or nnfm:
            return distances, torch.ones_like(distances)
        phi = distortion(match) if cfg.gt2 else torch.zeros_like(distances)
        level = depth_level(view.groups, cfg.n_scales, distances)
        weights = afcm_weight(
            level,
            view.frequency.to(distances),
            phi.to(distances),
            AFCMWeights(cfg.lambda_depth, cfg.lambda_frequency, cfg.lambda_distortion),
        )
        return distances, weights.detach()

    def _prior(self, v: int, view: ViewTargets) -> torch.Tensor:
        """Prior angle per cell: the start angle in the first view, else carried from the view before."""
        if view.link is None:
            angle = torch.full(view.mask.shape, float(self.config.angle) % 360.0, device=view.mask.device)
            return torch.where(view.mask, angle, torch.full_like(angle, math.nan))
        previous = self.order[self.order.index(v) - 1]
        if previous not in self.angle_maps:
            return self._unknown_angles(view)
        return view.link.prior_angles(self.angle_maps[previous])

    @staticmethod
    def _unknown_angles(view: ViewTargets) -> torch.Tensor:
        """No prior angle anywhere in ``view`` (NaN per cell, on the view's device)."""
        return torch.full(view.mask.shape, math.nan, device=view.mask.device)

    @torch.no_grad()
    def _push_along_hue_path(self) -> None:
        """*No New Hues*: every restyled splat's DC colour gradient keeps only what lightens, darkens or moves its hue
        along its way (``hue_path.along_hue_path``), so Adam's moments never hold a push that would be undone."""
        grad = self.scene.sh_dc.grad
        if grad is None:
            return
        rows = ~self.opt.frozen
        attached = self.opt.attachments
        grad[rows] = along_hue_path(
            grad[rows],
            self.scene.base_colors[rows],
            attached[COLOR_ATTACHMENT][rows],
            attached[OWN_COLOUR_ATTACHMENT][rows],
        )

    @torch.no_grad()
    def _hue_back_on_path(self) -> None:
        """*No New Hues*: every restyled splat's DC colour keeps its light, its hue put back on the way from its
        laid-out start's (``COLOR_ATTACHMENT``) to its own in the capture (``OWN_COLOUR_ATTACHMENT``)."""
        rows = ~self.opt.frozen
        attached = self.opt.attachments
        dc = self.scene.sh_dc
        colours = onto_hue_path(
            self.scene.base_colors[rows], attached[COLOR_ATTACHMENT][rows], attached[OWN_COLOUR_ATTACHMENT][rows]
        )
        dc[rows] = ((colours - 0.5) / SH_C0).to(dc)

    # -- correct (Geometry Preservation Branch) ---------------------------------------------------
    def correct_step(self) -> float:
        """One reconstruction step of the geometry against a random content image, rendered with c^g. On a view
        the geometry already fitted (no residual over the tolerance: no gradient) and has not moved since, with no
        momentum left to move it, the step is taken without drawing the view: what the drawing would give. A
        colour-only run's correct phases are all such steps once each view has been drawn."""
        cfg = self.config
        self.opt.set_trainable(GEOMETRY)
        v = int(torch.randint(len(self.views), (1,), generator=self.generator))
        if v in self.fitted and self.opt.at_rest():  # set_trainable left no gradient: a step with none
            self.opt.idle_step()
            self.report.correct_steps += 1
            self.report.fitted_correct_steps += 1
            return self.fitted[v]
        view = self.views[v]
        colors = self.opt.attachments[COLOR_ATTACHMENT]
        out = render(
            self.scene,
            [view.camera],
            colors=colors,
            background=self.background,
            backend=cfg.backend,
            render_depth=False,
        )
        loss = (
            reconstruction_loss(out.colors[0], view.content_image, tolerance=CORRECT_TOLERANCE)
            + cfg.lambda_scale * self._scale_term()
        )
        loss.backward()
        self._step(loss)
        value = float(loss.detach())
        if self.opt.at_rest() and math.isfinite(value):  # no gradient and no momentum: nothing moved, v fits
            self.fitted[v] = value
        else:
            self._geometry_moved()
        self.report.correct_steps += 1
        return value

    def _geometry_moved(self) -> None:
        """Forget what held only for the geometry as it was: each view's compositing weights and which views fit."""
        self.kept.clear()
        self.fitted.clear()

    def _scale_term(self) -> torch.Tensor:
        """The scale regulariser at each Gaussian's tolerated ratio."""
        return scale_regulariser(self.scene.log_scales, self.opt.attachments[RATIO_ATTACHMENT])

    def _step(self, loss: torch.Tensor) -> None:
        if not self.opt.step(loss):
            self.report.skipped_steps += 1
        self.opt.zero_grad()
