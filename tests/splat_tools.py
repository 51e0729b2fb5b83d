"""The oracle for the splat formats: PlayCanvas splat-transform (npm, pinned in package.json), and the
scenes the format tests convert with it."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
SPLAT_TRANSFORM = ROOT / "node_modules" / ".bin" / "splat-transform"
DONUT = ROOT.parent / "shared" / "data" / "scenes" / "donut" / "point_cloud.ply"


def core_names(k: int = 0) -> list[str]:
    """INRIA order of the Gaussian properties for K f_rest coefficients per channel, written out by hand so
    tests check the readers' and writers' tables against it."""
    return [
        "x",
        "y",
        "z",
        "f_dc_0",
        "f_dc_1",
        "f_dc_2",
        *(f"f_rest_{i}" for i in range(3 * k)),
        "opacity",
        "scale_0",
        "scale_1",
        "scale_2",
        "rot_0",
        "rot_1",
        "rot_2",
        "rot_3",
    ]


def splat_transform(*args: str | Path, timeout: float = 300) -> subprocess.CompletedProcess:
    """Run splat-transform (``-w``: overwrite) on files; fails the test with its output when it fails."""
    if not SPLAT_TRANSFORM.is_file() or shutil.which("node") is None:
        pytest.skip(f"splat-transform is not installed at {SPLAT_TRANSFORM}: run `npm ci` (make test does)")
    result = subprocess.run(
        [str(SPLAT_TRANSFORM), "-w", *map(str, args)], capture_output=True, text=True, timeout=timeout
    )
    assert result.returncode == 0, f"splat-transform {' '.join(map(str, args))} failed:\n{result.stdout}{result.stderr}"
    return result


def synthetic_scene(n: int = 2000, sh_degree: int = 3, seed: int = 0):
    """A small random scene with every SH band used: positions in a 2-unit box, log scales -5..-1,
    random unit quaternions, opacity logits -4..4, DC -1.5..1.5, rest bands -0.3..0.3 (SplatArrays)."""
    from gt2gs_blender.core.scene.arrays import SplatArrays

    rng = np.random.default_rng(seed)
    quats = rng.normal(size=(n, 4))
    quats /= np.linalg.norm(quats, axis=1, keepdims=True)
    k = (sh_degree + 1) ** 2 - 1
    return SplatArrays(
        means=rng.uniform(-1, 1, (n, 3)).astype(np.float32),
        quats=quats.astype(np.float32),
        log_scales=rng.uniform(-5, -1, (n, 3)).astype(np.float32),
        opacity_logits=rng.uniform(-4, 4, n).astype(np.float32),
        sh_dc=rng.uniform(-1.5, 1.5, (n, 3)).astype(np.float32),
        sh_rest=rng.uniform(-0.3, 0.3, (n, k, 3)).astype(np.float32),
        extras={},
    )


def donut_path() -> Path:
    """The shared donut, or a skip that says where it was looked for."""
    if not DONUT.is_file():
        pytest.skip(f"shared donut scene not found at {DONUT}")
    return DONUT


MADE_BY_SPLAT_TRANSFORM = {"compressed-ply": "donut.compressed.ply", "sog": "donut.sog", "spz": "donut.spz"}


def donut_in_every_format(folder: Path) -> dict[str, Path]:
    """The donut in every format, by format name: the shared PLY, three files splat-transform made from it,
    and a .splat our writer made (splat-transform does not write .splat)."""
    from gt2gs_blender.core.scene.files import write_splats
    from gt2gs_blender.core.scene.ply import read_ply_arrays

    files = {"ply": donut_path()}
    for fmt, name in MADE_BY_SPLAT_TRANSFORM.items():
        splat_transform(files["ply"], folder / name)
        files[fmt] = folder / name
    files["splat"] = folder / "donut.splat"
    write_splats(files["splat"], read_ply_arrays(files["ply"]))
    return files
