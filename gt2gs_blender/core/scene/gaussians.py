"""The Gaussian scene: the parameters of a 3DGS model as torch tensors, in their raw (pre-activation) form.

Raw parameters are what optimisers train and what INRIA PLY files store: log-scales, opacity logits,
un-normalised quaternions (w, x, y, z) and SH coefficients. Activations live here so every module
agrees on them.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np
import torch

from ..rotations import rotation_entries
from .arrays import PARAMETERS
from .inria import SH_C0, sh_coeff_count, sh_degree_from_rest

if TYPE_CHECKING:
    from .arrays import SplatArrays

LOG_SCALE_MAX = 88.0
"""Log-scales are clamped here before ``exp``: exp(88) ~ 1.7e38 is the largest float32 power of e, so a
scale never overflows to Inf (whose gradient, 0 * Inf, would be NaN)."""


@dataclass
class GaussianScene:
    """N Gaussians. Shapes: means (N,3), quats (N,4) w-first, log_scales (N,3), opacity_logits (N,),
    sh_dc (N,3), sh_rest (N,K,3) with K = (degree+1)^2 - 1.

    ``extras`` holds per-Gaussian PLY properties the engine does not use (normals, trainer-specific
    fields) as numpy arrays in file order, so that they survive a round trip. ``ply_layout`` is the
    source file's property order and types, used to write files back byte for byte.
    """

    means: torch.Tensor
    quats: torch.Tensor
    log_scales: torch.Tensor
    opacity_logits: torch.Tensor
    sh_dc: torch.Tensor
    sh_rest: torch.Tensor
    extras: dict[str, np.ndarray] = field(default_factory=dict)
    ply_layout: tuple[tuple[str, str], ...] | None = None

    def __post_init__(self) -> None:
        n = self.means.shape[0]
        expected = {
            "means": (n, 3),
            "quats": (n, 4),
            "log_scales": (n, 3),
            "opacity_logits": (n,),
            "sh_dc": (n, 3),
        }
        for name, shape in expected.items():
            actual = tuple(getattr(self, name).shape)
            if actual != shape:
                raise ValueError(f"GaussianScene.{name} has shape {actual}, expected {shape}")
        rest = tuple(self.sh_rest.shape)
        if len(rest) != 3 or rest[0] != n or rest[2] != 3:
            raise ValueError(f"GaussianScene.sh_rest has shape {rest}, expected ({n}, K, 3)")
        sh_degree_from_rest(rest[1])
        for key, value in self.extras.items():
            if value.shape[0] != n:
                raise ValueError(f"extra property {key!r} has {value.shape[0]} rows, expected {n}")

    # -- construction -------------------------------------------------------------------------------
    @classmethod
    def from_arrays(cls, arrays: SplatArrays) -> GaussianScene:
        """The scene of a file's numpy arrays (``SplatArrays``, as every splat reader returns them)."""
        tensors = {key: torch.from_numpy(np.ascontiguousarray(v)) for key, v in arrays.tensors().items()}
        return cls(**tensors, extras=arrays.extras, ply_layout=arrays.ply_layout)

    @classmethod
    def from_activated(
        cls,
        means: torch.Tensor,
        scales: torch.Tensor,
        opacities: torch.Tensor,
        colors: torch.Tensor,
        quats: torch.Tensor | None = None,
        sh_degree: int = 0,
    ) -> GaussianScene:
        """Build a scene from activated values: linear scales, opacities in (0,1), RGB in [0,1]."""
        n = means.shape[0]
        dtype, device = means.dtype, means.device
        if quats is None:
            quats = torch.zeros(n, 4, dtype=dtype, device=device)
            quats[:, 0] = 1.0
        eps = torch.finfo(dtype).eps
        op = opacities.clamp(eps, 1 - eps)
        return cls(
            means=means,
            quats=quats,
            log_scales=torch.log(scales.clamp_min(torch.finfo(dtype).tiny)),
            opacity_logits=torch.log(op) - torch.log1p(-op),
            sh_dc=(colors - 0.5) / SH_C0,
            sh_rest=torch.zeros(n, sh_coeff_count(sh_degree) - 1, 3, dtype=dtype, device=device),
        )

    # -- properties ---------------------------------------------------------------------------------
    def __len__(self) -> int:
        return int(self.means.shape[0])

    @property
    def sh_degree(self) -> int:
        return sh_degree_from_rest(int(self.sh_rest.shape[1]))

    @property
    def device(self) -> torch.device:
        return self.means.device

    @property
    def dtype(self) -> torch.dtype:
        return self.means.dtype

    @property
    def sh(self) -> torch.Tensor:
        """All SH coefficients (N, (degree+1)^2, 3), DC first."""
        return torch.cat([self.sh_dc[:, None, :], self.sh_rest], dim=1)

    # -- activations --------------------------------------------------------------------------------
    @property
    def scales(self) -> torch.Tensor:
        """Linear scales, finite for any finite log-scale (see ``LOG_SCALE_MAX``)."""
        return torch.exp(self.log_scales.clamp(max=LOG_SCALE_MAX))

    @property
    def opacities(self) -> torch.Tensor:
        return torch.sigmoid(self.opacity_logits)

    @property
    def rotations(self) -> torch.Tensor:
        """Unit quaternions (w, x, y, z); a zero quaternion maps to the identity rotation."""
        return normalize_quats(self.quats)

    @property
    def base_colors(self) -> torch.Tensor:
        """View-independent RGB from the DC band (what a viewer without SH would show)."""
        return 0.5 + SH_C0 * self.sh_dc

    def bounds(self, quantile: float = 1.0) -> tuple[torch.Tensor, torch.Tensor]:
        """Axis-aligned bounds of the means; ``quantile`` < 1 ignores stray outliers on each side."""
        if len(self) == 0:
            raise ValueError("an empty scene has no bounds")
        if quantile >= 1.0:
            return self.means.min(dim=0).values, self.means.max(dim=0).values
        q = torch.tensor([1.0 - quantile, quantile], dtype=self.means.dtype, device=self.device)
        lohi = torch.quantile(self.means.float(), q.float(), dim=0).to(self.means.dtype)
        return lohi[0], lohi[1]

    def finite_rows(self) -> torch.Tensor:
        """(N,) bool: the Gaussians all of whose parameters are finite (no NaN or Inf)."""
        rows = torch.ones(len(self), dtype=torch.bool, device=self.device)
        for tensor in self.tensors().values():
            rows &= torch.isfinite(tensor.detach()).reshape(len(self), -1).all(dim=1)
        return rows

    # -- structure ----------------------------------------------------------------------------------
    def tensors(self) -> dict[str, torch.Tensor]:
        """The trainable parameter tensors by name."""
        return {name: getattr(self, name) for name in PARAMETERS}

    def map_tensors(self, fn) -> GaussianScene:
        """A new scene with ``fn`` applied to every parameter tensor (extras untouched)."""
        return replace(self, **{k: fn(v) for k, v in self.tensors().items()})

    def subset(self, index: torch.Tensor | np.ndarray | slice) -> GaussianScene:
        """The Gaussians selected by a boolean mask, an index array or a slice."""
        if isinstance(index, torch.Tensor):
            np_index = index.detach().cpu().numpy()
            t_index = index.to(self.device)
        elif isinstance(index, np.ndarray):
            np_index = index
            t_index = torch.from_numpy(index).to(self.device)
        else:
            np_index = t_index = index
        return replace(
            self,
            **{k: v[t_index] for k, v in self.tensors().items()},
            extras={k: v[np_index] for k, v in self.extras.items()},
        )

    def to(self, device: torch.device | str | None = None, dtype: torch.dtype | None = None) -> GaussianScene:
        """Move (and optionally cast floating) tensors; extras stay numpy."""
        return self.map_tensors(lambda t: t.to(device=device, dtype=dtype))

    def detach(self) -> GaussianScene:
        return self.map_tensors(lambda t: t.detach())

    def clone(self) -> GaussianScene:
        out = self.map_tensors(lambda t: t.detach().clone())
        out.extras = {k: v.copy() for k, v in self.extras.items()}
        return out

    def with_sh_degree(self, degree: int) -> GaussianScene:
        """Truncate or zero-pad the SH bands to ``degree``."""
        k_new = sh_coeff_count(degree) - 1
        k_old = self.sh_rest.shape[1]
        if k_new <= k_old:
            rest = self.sh_rest[:, :k_new]
        else:
            pad = torch.zeros(len(self), k_new - k_old, 3, dtype=self.dtype, device=self.device)
            rest = torch.cat([self.sh_rest, pad], dim=1)
        return replace(self, sh_rest=rest, ply_layout=None)


def concat(scenes: Iterable[GaussianScene]) -> GaussianScene:
    """Concatenate scenes; SH degrees are raised to the highest, extras kept only if all share them."""
    scenes = list(scenes)
    if not scenes:
        raise ValueError("concat needs at least one scene")
    degree = max(s.sh_degree for s in scenes)
    scenes = [s if s.sh_degree == degree else s.with_sh_degree(degree) for s in scenes]
    common = [k for k in scenes[0].extras if all(k in s.extras for s in scenes[1:])]
    layouts = {s.ply_layout for s in scenes}
    return GaussianScene(
        **{k: torch.cat([s.tensors()[k] for s in scenes], dim=0) for k in scenes[0].tensors()},
        extras={k: np.concatenate([s.extras[k] for s in scenes]) for k in common},
        ply_layout=layouts.pop() if len(layouts) == 1 and len(common) == len(scenes[0].extras) else None,
    )


def normalize_quats(quats: torch.Tensor) -> torch.Tensor:
    """Unit quaternions; zero or non-finite ones become the identity (1, 0, 0, 0), with zero gradient.

    Non-finite quaternions are replaced before any arithmetic (a masked-out Inf would still make the
    gradient 0 * Inf = NaN), and each one is divided by its largest component before the norm, so
    float32 quaternions as large as 1e38 (whose squared norm overflows) still normalise correctly.
    """
    identity = torch.zeros_like(quats)
    identity[..., 0] = 1.0
    finite = torch.where(torch.isfinite(quats).all(dim=-1, keepdim=True), quats, identity)
    largest = finite.abs().amax(dim=-1, keepdim=True).clamp_min(torch.finfo(quats.dtype).tiny)
    unit_max = finite / largest
    norm = unit_max.norm(dim=-1, keepdim=True)
    ok = norm * largest > 1e-12
    return torch.where(ok, unit_max / norm.clamp_min(1e-12), identity)


def quats_to_rotmats(quats: torch.Tensor) -> torch.Tensor:
    """Rotation matrices (..., 3, 3) from quaternions (w, x, y, z); normalises first."""
    entries = rotation_entries(*normalize_quats(quats).unbind(-1))
    return torch.stack(entries, dim=-1).reshape((*quats.shape[:-1], 3, 3))
