"""``SplatArrays``: a Gaussian scene as numpy arrays, what every splat file reader returns and every writer takes.

numpy only, so Blender handles splats before the engine's torch is installed; ``GaussianScene.from_arrays``
turns it into the engine's tensors.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

PARAMETERS = ("means", "quats", "log_scales", "opacity_logits", "sh_dc", "sh_rest")
"""The per-Gaussian parameters of a scene, in order: the numpy arrays here, the tensors of GaussianScene."""


@dataclass
class SplatArrays:
    """The numpy twin of ``GaussianScene``: the same field names, shapes and meaning, float32 arrays."""

    means: np.ndarray
    quats: np.ndarray
    log_scales: np.ndarray
    opacity_logits: np.ndarray
    sh_dc: np.ndarray
    sh_rest: np.ndarray
    extras: dict[str, np.ndarray]
    ply_layout: tuple[tuple[str, str], ...] | None = None

    def __len__(self) -> int:
        return int(self.means.shape[0])

    def tensors(self) -> dict[str, np.ndarray]:
        """The parameter arrays by name (the keys of ``GaussianScene.tensors()``)."""
        return {name: getattr(self, name) for name in PARAMETERS}
