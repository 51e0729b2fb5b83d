"""What the worker tests share with the Blender edge's, torch-free (the edge's tests also run on a bpy whose
Python has no torch here): the small blob scene and stripe texture, the out-of-memory message, the capped
address space, and whether colours changed."""

from __future__ import annotations

import functools
import re
import resource
import subprocess
from pathlib import Path

import numpy as np
import pytest

from gt2gs_blender.blender.job import worker_python
from gt2gs_blender.core.errors import MEMORY_ADVICE
from gt2gs_blender.core.scene.arrays import SplatArrays
from gt2gs_blender.core.scene.inria import SH_C0

ROOT = Path(__file__).resolve().parents[1]
HEADROOM = 1 << 30
"""Address space a capped worker may add to what torch and the engine take once loaded: a tiny job
peaks ~150 MiB above that, a job at 4096 px needs several GiB."""
OUT_OF_MEMORY = re.compile(
    rf"ran out of memory( \(an allocation of [\d.]+ (bytes|MiB|GiB) failed\))?: "
    rf"{re.escape(MEMORY_ADVICE)}"
)
"""The message of a failed allocation: torch's allocators say the size; a bare MemoryError does not."""
needs_prlimit = pytest.mark.skipif(
    not hasattr(resource, "prlimit") or not Path("/proc/self/status").exists(),
    reason="capping another process's address space needs Linux",
)


@functools.cache
def address_space_cap() -> int:
    """Bytes of address space for a capped worker: what a fresh worker Python takes once torch and the
    engine are loaded (as the worker will have them), plus HEADROOM."""
    probe = (
        "import pathlib, gt2gs_blender.core.transfer.pipeline, gt2gs_blender.core.transfer.visibility; "
        "print(next(l.split()[1] for l in pathlib.Path('/proc/self/status').read_text().splitlines() "
        "if l.startswith('VmSize:')))"
    )
    result = subprocess.run(
        [worker_python(), "-c", probe], cwd=ROOT, capture_output=True, text=True, timeout=120, check=True
    )
    return int(result.stdout) * 1024 + HEADROOM


def colours_differ(a: np.ndarray, b: np.ndarray, tol: float = 0.02) -> bool:
    """Whether DC colours (N,3) changed: per Gaussian when the counts match, else (densified) on average."""
    if a.shape == b.shape:
        return float(np.abs(a - b).mean()) > tol
    return float(np.abs(a.mean(axis=0) - b.mean(axis=0)).max()) > tol


def stripes(size: int = 96) -> np.ndarray:
    """A high-contrast diagonal stripe texture."""
    y, x = np.mgrid[0:size, 0:size]
    band = ((x + y) // 6) % 2
    return np.stack([band * 0.9 + 0.05, band * 0.3 + 0.2, 1.0 - band * 0.8], axis=-1).astype(np.float32)


def blob_splats(n: int = 600, seed: int = 0) -> SplatArrays:
    """A fuzzy coloured ball of splats with an extra property (numpy's twin of test_transfer's blob_scene)."""
    rng = np.random.default_rng(seed)
    quats = rng.standard_normal((n, 4))
    colours = rng.random((n, 3)) * 0.5 + 0.25
    return SplatArrays(
        means=(rng.standard_normal((n, 3)) * 0.3).astype(np.float32),
        quats=(quats / np.linalg.norm(quats, axis=1, keepdims=True)).astype(np.float32),
        log_scales=np.full((n, 3), np.log(0.04), np.float32),
        opacity_logits=np.full(n, np.log(0.8 / 0.2), np.float32),
        sh_dc=((colours - 0.5) / SH_C0).astype(np.float32),
        sh_rest=np.zeros((n, 3, 3), np.float32),
        extras={"confidence": np.arange(n, dtype=np.float32)},
    )
