"""What the benchmarks share: generated scenes (so no data is needed) and the ``--set NAME=VALUE`` parser."""

from __future__ import annotations

import sys
from dataclasses import fields
from pathlib import Path
from typing import Any

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from gt2gs_blender.core.scene.gaussians import GaussianScene
from gt2gs_blender.core.transfer.config import TransferConfig, setting_type


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


def parse_overrides(pairs: list[str]) -> dict[str, Any]:
    """``name=value`` strings typed by the TransferConfig field they name (the config's own types)."""
    types = {f.name: f.type for f in fields(TransferConfig)}
    out: dict[str, Any] = {}
    for pair in pairs:
        name, sep, text = pair.partition("=")
        if not sep or name not in types:
            raise SystemExit(f"--set {pair!r}: expected NAME=VALUE with NAME one of {', '.join(types)}")
        annotation = str(types[name])
        if text == "None" and "None" in annotation:
            out[name] = None
            continue
        kind = setting_type(name)
        if kind is bool:
            if text.lower() not in ("1", "0", "true", "false", "yes", "no", "on", "off"):
                raise SystemExit(f"--set {pair!r}: not a yes/no value")
            out[name] = text.lower() in ("1", "true", "yes", "on")
        elif kind is tuple:
            out[name] = tuple(float(v) for v in text.split(","))
        else:
            out[name] = kind(text)
    return out
