"""Adam over a Gaussian scene's raw tensors, as 3DGS trains them, with masks and a non-finite guard.

What torch.optim.Adam cannot do for us: (1) freeze individual Gaussians so that they come out
bit-identical (Adam with a zero gradient still moves a parameter that has momentum, so frozen rows
are excluded from the update itself); (2) follow structure changes (densify, prune) row by row,
keeping survivors' moments and giving new Gaussians zero moments; (3) skip a step whose loss,
gradient or update is not finite instead of spreading NaNs into the scene, log it, and halve the
learning rates when such steps repeat (:class:`StepGuard`, usable with any optimiser).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterable
from dataclasses import dataclass, replace

import torch

from ..scene.arrays import PARAMETERS as PARAM_NAMES
from ..scene.gaussians import GaussianScene

BACKOFF_AFTER = 3
"""Consecutive skipped steps after which the learning rates are halved."""
MIN_LR_SCALE = 2.0**-10
"""The learning-rate multiplier never backs off below this (1/1024)."""

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class LearningRates:
    """Per-tensor Adam learning rates of 3DGS. ``means`` decays exponentially from ``means`` to
    ``means_final`` over the run, both multiplied by the scene extent. Opacity uses the original
    paper's 0.05 (newer 3DGS code uses 0.025): short CPU runs need opacities to settle fast."""

    means: float = 1.6e-4
    means_final: float = 1.6e-6
    quats: float = 1e-3
    log_scales: float = 5e-3
    opacity_logits: float = 0.05
    sh_dc: float = 2.5e-3
    sh_rest: float = 2.5e-3 / 20.0

    def at(self, step: int, total: int, extent: float) -> dict[str, float]:
        """The learning rate of every tensor at ``step`` of ``total``."""
        lrs = {name: getattr(self, name) for name in PARAM_NAMES}
        lrs["means"] = extent * exponential_decay(step, total, self.means, self.means_final)
        return lrs


def exponential_decay(step: int, total: int, start: float, end: float) -> float:
    """Log-linear interpolation from ``start`` (step 0) to ``end`` (step ``total`` and after)."""
    t = min(max(step / max(total, 1), 0.0), 1.0)
    return math.exp((1.0 - t) * math.log(start) + t * math.log(end))


def step_scale(second_moment: torch.Tensor, shared: bool) -> torch.Tensor:
    """Adam's divisor, the root of the (bias-corrected) second moment: per element, or with ``shared`` one per
    colour, the root of its mean over the last axis (R, G, B). Per element, a step even in R, G and B (lighter or
    darker) comes out uneven, a hue, wherever the channels' histories differ; shared, each colour's step points
    where its momentum points."""
    return (second_moment.mean(-1, keepdim=True) if shared else second_moment).sqrt()


def rows_like(mask: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
    """A per-Gaussian (N,) mask reshaped to broadcast against a per-Gaussian tensor (N, ...)."""
    return mask.reshape(-1, *([1] * (t.dim() - 1)))


class StepGuard:
    """Decides whether an optimisation step may run: not when the loss or a gradient is NaN/Inf.

    Each skipped step is logged (warning) and counted; after ``backoff_after`` consecutive skips the
    learning-rate multiplier ``lr_scale`` is halved (down to ``MIN_LR_SCALE``, logged), since a step
    that keeps blowing up usually means a step size that is too large. A taken step resets the run
    of skips but not ``lr_scale``.
    """

    def __init__(self, backoff_after: int = BACKOFF_AFTER) -> None:
        self.backoff_after = backoff_after
        self.lr_scale = 1.0
        self.skipped = 0
        self.consecutive = 0

    def allow(self, loss: torch.Tensor | float | None, grads: dict[str, torch.Tensor | None]) -> bool:
        """True when ``loss`` and every gradient are finite; otherwise record a skipped step."""
        value = float(loss.detach()) if isinstance(loss, torch.Tensor) else loss
        if value is not None and not math.isfinite(value):
            return self.skip(f"the loss is {value}")
        bad = [name for name, g in grads.items() if g is not None and not bool(torch.isfinite(g).all())]
        if bad:
            return self.skip(f"non-finite gradient of {', '.join(bad)}")
        self.consecutive = 0
        return True

    def skip(self, reason: str) -> bool:
        """Record a skipped step (always False), backing off the learning rate when skips repeat."""
        self.skipped += 1
        self.consecutive += 1
        log.warning("optimisation step skipped: %s (%d skipped so far)", reason, self.skipped)
        if self.consecutive % self.backoff_after == 0 and self.lr_scale > MIN_LR_SCALE:
            self.lr_scale = max(self.lr_scale * 0.5, MIN_LR_SCALE)
            log.warning(
                "%d steps in a row were not finite: learning rates scaled to %g of their schedule",
                self.consecutive,
                self.lr_scale,
            )
        return False


class GaussianAdam:
    """Adam (eps 1e-15 as in 3DGS) over ``scene``'s tensors.

    ``trainable`` names the tensors that learn; ``frozen`` (N,) marks Gaussians that never change.
    ``attachments`` are per-Gaussian tensors that are not trained but must follow every structure
    change (e.g. the geometry-preservation colours). ``shared_channels`` names colour tensors whose R, G
    and B share one step size (:func:`step_scale`). ``scene`` (a copy of the one given) is replaced on
    structure changes; its tensors are leaves updated in place by :meth:`step`.
    """

    def __init__(
        self,
        scene: GaussianScene,
        lrs: dict[str, float],
        *,
        trainable: Iterable[str] = PARAM_NAMES,
        frozen: torch.Tensor | None = None,
        attachments: dict[str, torch.Tensor] | None = None,
        shared_channels: Iterable[str] = (),
        betas: tuple[float, float] = (0.9, 0.999),
        eps: float = 1e-15,
    ) -> None:
        n = len(scene)
        self.lrs = dict(lrs)
        self.betas, self.eps = betas, eps
        self.trainable = _check_names(trainable)
        self.shared_channels = _check_names(shared_channels)
        self.frozen = (
            torch.zeros(n, dtype=torch.bool, device=scene.device)
            if frozen is None
            else frozen.to(device=scene.device, dtype=torch.bool).clone()
        )
        if self.frozen.shape != (n,):
            raise ValueError(f"frozen mask has shape {tuple(self.frozen.shape)}, expected ({n},)")
        self.attachments = {k: v.detach().clone() for k, v in (attachments or {}).items()}
        self.scene = self._leaves(scene.clone())  # trained in place: never the caller's tensors
        self.exp_avg = {k: torch.zeros_like(v) for k, v in self.scene.tensors().items()}
        self.exp_avg_sq = {k: torch.zeros_like(v) for k, v in self.scene.tensors().items()}
        self.steps = 0
        self.guard = StepGuard()

    # -- training -----------------------------------------------------------------------------------
    def set_trainable(self, names: Iterable[str]) -> None:
        """Change which tensors learn (moments of the others are kept for when they learn again)."""
        self.trainable = _check_names(names)
        self.scene = self._leaves(self.scene)

    def zero_grad(self) -> None:
        for t in self.scene.tensors().values():
            t.grad = None

    @property
    def skipped(self) -> int:
        """Steps skipped because the loss, a gradient or an update was not finite."""
        return self.guard.skipped

    def at_rest(self) -> bool:
        """Whether a step with no gradient would move nothing: every trainable tensor's first moment is zero
        (none has had a gradient yet, or it has decayed away)."""
        return not any(bool(self.exp_avg[name].any()) for name in self._trained())

    def idle_step(self) -> None:
        """What :meth:`step` does with no gradient while :meth:`at_rest`, without its arithmetic on every value:
        nothing moves, the second moments decay and the step counts in the bias correction (bit for bit)."""
        b2 = self.betas[1]
        keep_frozen = bool(self.frozen.any())
        with torch.no_grad():
            for name, param in self._trained().items():
                v = self.exp_avg_sq[name] * b2
                if keep_frozen:
                    v = torch.where(rows_like(~self.frozen, param), v, self.exp_avg_sq[name])
                self.exp_avg_sq[name] = v
        self.guard.allow(None, {})  # a taken step: ends a run of skipped ones, as step's does
        self.steps += 1

    def step(self, loss: torch.Tensor | None = None) -> bool:
        """One Adam update of the trainable tensors on the unfrozen rows, at the learning rates times
        ``guard.lr_scale``. False (counted in ``skipped``, logged) when ``loss``, a gradient or the
        update is not finite, in which case nothing changes: the scene never receives NaN or Inf."""
        if not self.guard.allow(loss, {k: v.grad for k, v in self._trained().items()}):
            return False
        b1, b2 = self.betas
        bc1, bc2 = 1.0 - b1 ** (self.steps + 1), 1.0 - b2 ** (self.steps + 1)
        active = ~self.frozen
        any_frozen = bool(self.frozen.any())
        pending: dict[str, tuple[torch.Tensor, ...]] = {}
        with torch.no_grad():
            for name, param in self._trained().items():
                grad = torch.zeros_like(param) if param.grad is None else param.grad
                m = self.exp_avg[name] * b1 + grad * (1.0 - b1)
                v = self.exp_avg_sq[name] * b2 + grad * grad * (1.0 - b2)
                scale = step_scale(v / bc2, name in self.shared_channels)
                update = (m / bc1) / (scale + self.eps) * (self.lrs[name] * self.guard.lr_scale)
                if any_frozen:
                    keep = rows_like(active, param)
                    m = torch.where(keep, m, self.exp_avg[name])
                    v = torch.where(keep, v, self.exp_avg_sq[name])
                    update = torch.where(keep, update, torch.zeros_like(update))
                new = param - update
                if not bool(torch.isfinite(new).all()):
                    return self.guard.skip(f"the update of {name} is not finite")
                pending[name] = (param, m, v, new)
            for name, (param, m, v, new) in pending.items():
                self.exp_avg[name], self.exp_avg_sq[name] = m, v
                param.copy_(new)
        self.steps += 1
        return True

    # -- structure changes --------------------------------------------------------------------------
    def restructure(self, source: torch.Tensor, n_kept: int, values: dict[str, torch.Tensor] | None = None) -> None:
        """Rebuild the Gaussians as rows ``source`` of the current ones (kept rows first, then
        ``len(source) - n_kept`` new rows copied from their parents). ``values`` overrides tensors of
        the new rows. Survivors keep their values, moments and masks exactly; new rows get zero
        moments and inherit their parent's frozen flag, attachments and extras."""
        changes = {}
        for name, t in self.scene.tensors().items():
            t = t.detach()[source]
            if values is not None and name in values:
                t[n_kept:] = values[name].to(t.dtype)
            changes[name] = t
        rows = source.cpu().numpy()
        extras = {k: v[rows] for k, v in self.scene.extras.items()}
        self.scene = self._leaves(replace(self.scene, extras=extras, **changes))
        for moments in (self.exp_avg, self.exp_avg_sq):
            for name, t in moments.items():
                moments[name] = t[source]
                moments[name][n_kept:] = 0.0
        self.frozen = self.frozen[source]
        self.attachments = {k: v[source] for k, v in self.attachments.items()}

    def assign(self, name: str, rows: torch.Tensor, values: torch.Tensor) -> None:
        """Set a tensor's ``rows`` (bool mask) to ``values`` and zero their moments (a fresh start,
        as 3DGS does for the opacity reset)."""
        param = self.scene.tensors()[name]
        with torch.no_grad():
            param[rows] = values.to(param.dtype)
        self.exp_avg[name][rows] = 0.0
        self.exp_avg_sq[name][rows] = 0.0

    # -- helpers ------------------------------------------------------------------------------------
    def _trained(self) -> dict[str, torch.Tensor]:
        return {k: v for k, v in self.scene.tensors().items() if k in self.trainable}

    def _leaves(self, scene: GaussianScene) -> GaussianScene:
        """The scene with detached leaf tensors requiring grad exactly where trainable."""
        return replace(scene, **{k: v.detach().requires_grad_(k in self.trainable) for k, v in scene.tensors().items()})


def _check_names(names: Iterable[str]) -> frozenset[str]:
    names = frozenset(names)
    unknown = names - set(PARAM_NAMES)
    if unknown:
        raise ValueError(f"unknown scene tensors {sorted(unknown)}; trainable ones are {', '.join(PARAM_NAMES)}")
    return names
