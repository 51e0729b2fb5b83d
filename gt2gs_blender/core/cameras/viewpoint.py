"""Where a capture's cameras stood, read from its splats' sizes: a trained splat's footprint matches the pixels it
was trained from, so its size grows with its distance from the cameras that saw it. Views for a capture seen from
the front, given without its cameras, stand on that side; for one seen from inside (a room), where they stood."""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F

from ..scene.gaussians import GaussianScene

OPAQUE = 0.5
"""Only splats above this opacity are read: faint ones are the optimiser's leftovers, their sizes say little."""
SAMPLE = 20_000
"""At most this many splats (drawn with a fixed seed): from 80,000 of the guitar's and the robot's the direction moves
under 1° and the gain 0.002; the fit takes under a second (the donut 0.4 s, the guitar 0.6 s on 2 cores)."""
HUBER = 0.5
"""Residuals beyond this in log size (x1.65) count linearly: a few huge background splats do not pull the point."""
QUANTILE = 0.02
"""The capture's middle and extent: the box between these quantiles of the read splats' centres (floaters aside)."""
MIN_SPLATS = 16
"""Fewer opaque splats than this say nothing of where the cameras stood."""
MIN_GAIN = 0.1
"""Below this gain the sizes do not say where the cameras stood: captures seen all round read 0.03-0.04 (the guitar,
the robot, whose fitted point lay under its ground), the fern seen from the front 0.30."""
INSIDE_CORE = 0.3
"""Cameras stood inside a capture when the point lies within this share of its box from the middle along every axis
(the donut's point lies 0.93 of its box above it, the fern's many boxes out towards its cameras)."""
ENCLOSING_SIDES = 4
ENCLOSING_SHARE = 0.02
"""... and splats lie all round it: at least this many of the six directions along the world axes each hold this
share of the read splats, those whose direction from the point lies nearest that axis (a room's four walls: seen
from eye height, most of its floor and ceiling lie nearer a wall's direction than straight down or up)."""
EMPTY_RADIUS = 0.1
EMPTY_SHARE = 0.05
"""... and the point stands in the open: under this share of the read splats lie within this share of the extent of
it (a room's cameras stand in its air; a capture walked round an object, its surroundings kept, as Mip-NeRF 360's
garden, holds a third of its splats that near its middle: its table)."""


@dataclass(frozen=True)
class Viewpoint:
    """Where the cameras stood: ``point`` (3,) world, the capture's ``middle`` (3,) and ``extent`` (its box's
    diagonal), ``gain``, how much better than one size for all the distance explains the sizes (0: not at all;
    a capture seen from one side 0.3, one seen all round 0.03-0.17), and ``enclosed``, whether the point lies in
    the capture's core, in the open, with splats all round it (``INSIDE_CORE``, ``EMPTY_SHARE``,
    ``ENCLOSING_SIDES``)."""

    point: np.ndarray
    middle: np.ndarray
    extent: float
    gain: float
    enclosed: bool

    @property
    def telling(self) -> bool:
        """Whether the sizes say where the cameras stood (``gain`` at least ``MIN_GAIN``)."""
        return self.gain >= MIN_GAIN

    @property
    def inside(self) -> bool:
        """Whether the cameras stood inside the capture (a room seen from within): telling and ``enclosed``."""
        return self.telling and self.enclosed

    @property
    def direction(self) -> np.ndarray:
        """Unit direction from the middle towards the point."""
        away = self.point - self.middle
        return away / max(float(np.linalg.norm(away)), 1e-12)


def fitted_viewpoint(scene: GaussianScene, count: int = SAMPLE) -> Viewpoint | None:
    """The point whose distance best explains the opaque splats' middle scales (log scale = log k + log distance,
    Huber loss, from seven starts: one extent out along each axis, and the capture's middle, where a room's cameras
    stood, the best kept); None for fewer than ``MIN_SPLATS`` opaque splats, a capture with no extent or a fit
    that diverged from every start."""
    centres, log_size = _sample(scene, count)
    if len(centres) < MIN_SPLATS:
        return None
    key = hashlib.blake2b(centres.numpy().tobytes() + log_size.numpy().tobytes(), digest_size=16).digest()
    if key not in _FITTED:
        _FITTED[key] = _fit(centres, log_size)
        while len(_FITTED) > CACHED:
            _FITTED.pop(next(iter(_FITTED)))
    return _FITTED[key]


CACHED = 4
"""Fits kept, by the read splats' content: a run reads one scene's several times (its size probe, its views, the
visibility check, the before/after strip)."""
_FITTED: dict[bytes, Viewpoint | None] = {}


def _fit(centres: torch.Tensor, log_size: torch.Tensor) -> Viewpoint | None:
    """:func:`fitted_viewpoint` of the read splats."""
    lo, hi = (torch.quantile(centres, q, dim=0) for q in (QUANTILE, 1.0 - QUANTILE))
    middle, extent = (lo + hi) / 2.0, float((hi - lo).norm())
    if not extent > 0.0:
        return None
    scale = (log_size.median() - math.log(extent)).reshape(1)
    offsets = torch.cat([torch.eye(3), -torch.eye(3), torch.zeros(1, 3)]).double() * extent
    starts = [torch.cat([middle + offset, scale]) for offset in offsets]
    nearest = (1e-12 * extent) ** 2
    point, fitted = min((_minimised(centres, log_size, start, nearest) for start in starts), key=lambda fit: fit[1])
    if not math.isfinite(fitted):
        return None
    flat = _huber(log_size - log_size.median())
    gain = 1.0 - fitted / flat if flat > 0.0 else 0.0
    at, centre = point[:3].numpy(), middle.numpy()
    at.setflags(write=False)  # shared by every caller the cache answers
    centre.setflags(write=False)
    return Viewpoint(at, centre, extent, gain, _enclosed(centres.numpy(), at, lo.numpy(), hi.numpy()))


def _enclosed(centres: np.ndarray, point: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> bool:
    """Whether ``point`` lies within ``INSIDE_CORE`` of the box ``lo``-``hi`` from its middle on every axis, in the
    open (``EMPTY_SHARE``) and at least ``ENCLOSING_SIDES`` of the six axis directions from it each hold
    ``ENCLOSING_SHARE`` of ``centres``."""
    size = np.maximum(hi - lo, 1e-12)
    if np.any(np.abs(point - (lo + hi) / 2.0) > INSIDE_CORE * size):
        return False
    away = centres - point
    if np.mean(np.linalg.norm(away, axis=1) < EMPTY_RADIUS * float(np.linalg.norm(hi - lo))) >= EMPTY_SHARE:
        return False
    axis = np.argmax(np.abs(away), axis=1)
    positive = away[np.arange(len(away)), axis] > 0
    shares = np.bincount(2 * axis + positive, minlength=6) / max(len(away), 1)
    return int(np.count_nonzero(shares >= ENCLOSING_SHARE)) >= ENCLOSING_SIDES


def _sample(scene: GaussianScene, count: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Centres (n, 3) and log middle scales (n,) of up to ``count`` opaque splats with finite sizes, float64."""
    scales = torch.sort(scene.scales.detach().double().cpu(), dim=1).values[:, 1]
    log_size = scales.clamp_min(torch.finfo(torch.float64).tiny).log()
    centres = scene.means.detach().double().cpu()
    keep = torch.isfinite(log_size) & torch.isfinite(centres).all(dim=1)
    keep &= scene.opacities.detach().double().cpu().reshape(-1) > OPAQUE
    centres, log_size = centres[keep], log_size[keep]
    pick = torch.randperm(len(centres), generator=torch.Generator().manual_seed(0))[:count]
    return centres[pick], log_size[pick]


STEPS = 200
"""At most this many Levenberg-Marquardt steps from a start (each fit of the shared scenes settles within 40)."""


def _huber(residual: torch.Tensor) -> float:
    """The mean Huber loss (``HUBER``) of ``residual``."""
    return float(F.huber_loss(residual, torch.zeros_like(residual), delta=HUBER))


def _minimised(
    centres: torch.Tensor, log_size: torch.Tensor, start: torch.Tensor, nearest: float
) -> tuple[torch.Tensor, float]:
    """The point and log factor (4,) from ``start`` that minimise the Huber loss of log size - log k - log distance
    (squared distances held above ``nearest``), and the loss there (inf where it diverged): Levenberg-Marquardt on
    the loss's reweighted least squares, a 4 x 4 solve a step. It finds the minima L-BFGS found to a thousandth of
    a unit, 3-7x faster, and needs no torch.optim, whose first optimiser imports its compiler (1.3 s)."""

    def residuals(p: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        away = centres - p[:3]
        squared = (away * away).sum(dim=1).clamp_min(nearest)
        return away, squared, log_size - p[3] - 0.5 * squared.log()

    p, damping = start.clone(), 1e-3
    away, squared, r = residuals(p)
    value = _huber(r)
    for _ in range(STEPS):
        weight = (HUBER / r.abs().clamp_min(1e-300)).clamp(max=1.0)
        jacobian = torch.cat([away / squared[:, None], -torch.ones_like(r)[:, None]], dim=1)
        normal = jacobian.T @ (weight[:, None] * jacobian)
        gradient = jacobian.T @ (weight * r)
        while damping < 1e12:
            step = torch.linalg.solve(normal + damping * torch.diag(normal.diagonal().clamp_min(1e-300)), -gradient)
            trial = residuals(p + step)
            trial_value = _huber(trial[2])
            if trial_value < value:
                break
            damping *= 4.0
        else:
            break
        p, (away, squared, r), damping = p + step, trial, damping / 3.0
        gained, value = value - trial_value, trial_value
        if gained <= 1e-12 * value:
            break
    finite = math.isfinite(value) and bool(torch.isfinite(p).all())
    return p, value if finite else math.inf
