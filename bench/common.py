"""Scenes shared by the benchmarks (generated, so no data is needed)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from gt2gs_blender.core.scene.gaussians import GaussianScene


def random_scene(n: int, degree: int = 3, seed: int = 0) -> GaussianScene:
    """A random SH-``degree`` scene with normals, as the INRIA trainer writes it."""
    g = torch.Generator().manual_seed(seed)
    k = (degree + 1) ** 2 - 1
    normals = np.zeros(n, np.float32)
    return GaussianScene(
        means=torch.randn(n, 3, generator=g),
        quats=torch.randn(n, 4, generator=g),
        log_scales=torch.randn(n, 3, generator=g) - 4,
        opacity_logits=torch.randn(n, generator=g),
        sh_dc=torch.randn(n, 3, generator=g),
        sh_rest=torch.randn(n, k, 3, generator=g) * 0.1,
        extras={"nx": normals, "ny": normals.copy(), "nz": normals.copy()},
    )
