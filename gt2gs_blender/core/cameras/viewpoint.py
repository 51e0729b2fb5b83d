"""Where a capture's cameras stood, read from its splats' sizes: a trained splat's footprint matches the pixels it
was trained from, so its size grows with its distance from the cameras that saw it. Views for a capture seen from
the front, given without its cameras, stand on that side."""

from __future__ import annotations

import hashlib
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F

from ..scene.gaussians import GaussianScene

OPAQUE = 0.5
"""Only splats above this opacity are read: faint ones are the optimiser's leftovers, their sizes say little."""
SAMPLE = 20_000
"""At most this many splats (drawn with a fixed seed): from 80,000 of the guitar's and the robot's the direction moves
under 1° and the gain 0.002; the fit takes seconds (the fern's 8,000 opaque splats 1.7 s on 2 cores)."""
HUBER = 0.5
"""Residuals beyond this in log size (x1.65) count linearly: a few huge background splats do not pull the point."""
QUANTILE = 0.02
"""The capture's middle and extent: the box between these quantiles of the read splats' centres (floaters aside)."""
MIN_SPLATS = 16
"""Fewer opaque splats than this say nothing of where the cameras stood."""
MIN_GAIN = 0.1
"""Below this gain the sizes do not say where the cameras stood: captures seen all round read 0.03-0.04 (the guitar,
the robot, whose fitted point lay under its ground), the fern seen from the front 0.30."""


@dataclass(frozen=True)
class Viewpoint:
    """Where the cameras stood: ``point`` (3,) world, the capture's ``middle`` (3,) and ``extent`` (its box's
    diagonal), and ``gain``, how much better than one size for all the distance explains the sizes (0: not at all;
    a capture seen from one side 0.3, one seen all round 0.03-0.17)."""

    point: np.ndarray
    middle: np.ndarray
    extent: float
    gain: float

    @property
    def telling(self) -> bool:
        """Whether the sizes say where the cameras stood (``gain`` at least ``MIN_GAIN``)."""
        return self.gain >= MIN_GAIN

    @property
    def direction(self) -> np.ndarray:
        """Unit direction from the middle towards the point."""
        away = self.point - self.middle
        return away / max(float(np.linalg.norm(away)), 1e-12)


def fitted_viewpoint(scene: GaussianScene, count: int = SAMPLE) -> Viewpoint | None:
    """The point whose distance best explains the opaque splats' middle scales (log scale = log k + log distance,
    Huber loss, L-BFGS from six starts one extent out along each axis, the best kept); None for fewer than
    ``MIN_SPLATS`` opaque splats, a capture with no extent or a fit that diverged from every start."""
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

    def loss(p: torch.Tensor) -> torch.Tensor:
        residual = log_size - p[3] - (centres - p[:3]).norm(dim=1).clamp_min(1e-12 * extent).log()
        return F.huber_loss(residual, torch.zeros_like(residual), delta=HUBER)

    scale = (log_size.median() - math.log(extent)).reshape(1)
    starts = [torch.cat([middle + axis * extent, scale]) for axis in torch.cat([torch.eye(3), -torch.eye(3)]).double()]
    point, fitted = min((_minimised(loss, start) for start in starts), key=lambda fit: fit[1])
    if not math.isfinite(fitted):
        return None
    flat = float(F.huber_loss(log_size, torch.full_like(log_size, float(log_size.median())), delta=HUBER))
    gain = 1.0 - fitted / flat if flat > 0.0 else 0.0
    at, centre = point[:3].numpy(), middle.numpy()
    at.setflags(write=False)  # shared by every caller the cache answers
    centre.setflags(write=False)
    return Viewpoint(at, centre, extent, gain)


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


def _minimised(loss: Callable[[torch.Tensor], torch.Tensor], start: torch.Tensor) -> tuple[torch.Tensor, float]:
    """``loss``'s minimum from ``start`` by L-BFGS: the parameters and the loss there (inf where it diverged)."""
    p = start.clone().requires_grad_(True)
    optimiser = torch.optim.LBFGS([p], max_iter=300, line_search_fn="strong_wolfe")

    def closure() -> torch.Tensor:
        optimiser.zero_grad()
        value = loss(p)
        value.backward()
        return value

    with torch.enable_grad():
        optimiser.step(closure)
    with torch.no_grad():
        value = float(loss(p))
    return p.detach(), value if math.isfinite(value) and bool(torch.isfinite(p).all()) else math.inf
