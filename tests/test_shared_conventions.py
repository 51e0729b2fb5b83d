"""The 3DGS conventions have one home: ``core.scene.inria`` (PLY names, SH_C0) and ``core.rotations``
(quaternion -> matrix), used by core, the COLMAP reader and the Blender edge's bake (no bpy needed).

Oracles: rotations are checked against q v q* with a hand-written Hamilton product; the torch twin
``quats_to_rotmats`` must agree; the bake is checked against its own parts kept as they were.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from gt2gs_blender.blender import transform
from gt2gs_blender.core.rotations import quats_to_matrices
from gt2gs_blender.core.scene import inria
from gt2gs_blender.core.scene.arrays import SplatArrays
from gt2gs_blender.core.scene.gaussians import quats_to_rotmats

from .splat_tools import core_names

PACKAGE = Path(__file__).resolve().parents[1] / "gt2gs_blender"


def hamilton(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a ⊗ b for single quaternions (w, x, y, z)."""
    aw, av, bw, bv = a[0], a[1:], b[0], b[1:]
    return np.r_[aw * bw - av @ bv, aw * bv + bw * av + np.cross(av, bv)]


def rotation_by_conjugation(q: np.ndarray) -> np.ndarray:
    """The matrix whose columns are q e_i q* for the unit quaternion of ``q``."""
    q = q / np.linalg.norm(q)
    conj = q * np.r_[1.0, -1.0, -1.0, -1.0]
    return np.stack([hamilton(hamilton(q, np.r_[0.0, e]), conj)[1:] for e in np.eye(3)], axis=1)


def test_quats_to_matrices_normalises_and_matches_q_v_q_conjugate():
    quats = np.random.default_rng(0).normal(size=(50, 4)) * np.logspace(-6, 6, 50)[:, None]
    mats = quats_to_matrices(quats)
    assert mats.shape == (50, 3, 3) and mats.dtype == np.float64
    for q, m in zip(quats, mats):
        np.testing.assert_allclose(m, rotation_by_conjugation(q), atol=1e-12)
    np.testing.assert_allclose(quats_to_matrices(quats[7]), mats[7], atol=0)  # a single (4,) quaternion
    np.testing.assert_allclose(mats, quats_to_rotmats(torch.from_numpy(quats)).numpy(), atol=1e-12)


def test_degenerate_zero_quaternion_is_the_identity():
    quats = np.array([[0.0, 0.0, 0.0, 0.0], [1e-13, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 2.0]])
    mats = quats_to_matrices(quats)
    np.testing.assert_array_equal(mats[0], np.eye(3))
    np.testing.assert_array_equal(mats[1], np.eye(3))
    np.testing.assert_allclose(mats[2], np.diag([-1.0, -1.0, 1.0]), atol=1e-15)


def test_inria_names_and_sh_layout():
    assert inria.SH_C0 == 0.28209479177387814
    assert tuple(core_names(0)) == inria.REQUIRED
    names = inria.core_property_names(3)
    assert names[6:15] == [f"f_rest_{i}" for i in range(9)] and names[15] == "opacity"
    assert [inria.rest_per_channel(f"f_rest_{i}" for i in range(n)) for n in (0, 9, 24, 45)] == [0, 3, 8, 15]
    assert inria.rest_per_channel(["f_rest_0"] * 9) is None
    assert inria.rest_per_channel(f"f_rest_{i}" for i in range(1, 10)) is None
    assert [inria.sh_degree_from_rest(k) for k in (0, 3, 8, 15)] == [0, 1, 2, 3]
    storage = np.arange(2 * 9).reshape(2, 9)  # channel-major: R's 3 coefficients, then G's, then B's
    np.testing.assert_array_equal(inria.tensor_view("sh_rest", storage)[1, :, 0], [9, 10, 11])


@pytest.mark.parametrize("literal", ["0.28209479177387814", "1 - 2 * (y * y + z * z)", "ALPHA_MIN = "])
def test_conventions_are_written_once_in_the_package(literal):
    """SH_C0 lives in core/scene/inria.py; the quaternion formula in core/rotations.py only (numpy, torch and the
    numba kernel all call it); the rasterizer's alpha rules in core/raster_rules.py (every backend and Blender's
    display read them)."""
    homes = {
        "0.28209479177387814": {"core/scene/inria.py"},
        "1 - 2 * (y * y + z * z)": {"core/rotations.py"},
        "ALPHA_MIN = ": {"core/raster_rules.py"},
    }[literal]
    found = {str(p.relative_to(PACKAGE)) for p in PACKAGE.rglob("*.py") if literal in p.read_text(encoding="utf-8")}
    assert found == homes


def test_the_blender_edge_declares_no_ply_name_table():
    """No literal "f_dc_0".."rot_3" tuples or 'x', 'y', 'z' lists in blender/: they come from core."""
    pattern = re.compile(r"[\"'](?:f_dc_\d|scale_\d|rot_\d|nx)[\"']")
    offenders = [p.name for p in (PACKAGE / "blender").glob("*.py") if pattern.search(p.read_text(encoding="utf-8"))]
    assert offenders == []


def covariances(scene: SplatArrays) -> np.ndarray:
    """R S Sᵀ Rᵀ per Gaussian, in float64."""
    m = quats_to_matrices(scene.quats) * np.exp(scene.log_scales.astype(np.float64))[:, None, :]
    return m @ m.transpose(0, 2, 1)


def splat_arrays(n: int = 40, k: int = 8, seed: int = 0) -> SplatArrays:
    """Random Gaussians with SH degree 2, normals of mixed float types and an integer extra."""
    rng = np.random.default_rng(seed)
    normals = rng.normal(size=(n, 3))
    return SplatArrays(
        means=rng.normal(size=(n, 3)).astype(np.float32),
        quats=rng.normal(size=(n, 4)).astype(np.float32),
        log_scales=rng.normal(size=(n, 3)).astype(np.float32),
        opacity_logits=rng.normal(size=n).astype(np.float32),
        sh_dc=rng.normal(size=(n, 3)).astype(np.float32),
        sh_rest=rng.normal(size=(n, k, 3)).astype(np.float32),
        extras={
            "nx": normals[:, 0].astype(np.float32),
            "label": np.arange(n, dtype=np.uint8),
            "ny": normals[:, 1],
            "nz": normals[:, 2].astype(np.float32),
        },
        ply_layout=(("x", "float"),),
    )


@pytest.mark.parametrize(
    "linear", [np.diag([2.0, 2.0, 2.0]) @ np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1.0]]), np.diag([1.0, 3.0, -0.5])]
)
def test_bake_works_on_splat_arrays_and_leaves_the_input_alone(linear):
    scene = splat_arrays()
    before = {key: value.copy() for key, value in scene.tensors().items()}
    matrix = np.eye(4)
    matrix[:3, :3], matrix[:3, 3] = linear, (1.0, -2.0, 0.5)
    baked, notes = transform.bake(scene, matrix)

    assert isinstance(baked, SplatArrays) and baked.ply_layout == scene.ply_layout
    for key, value in before.items():
        np.testing.assert_array_equal(scene.tensors()[key], value)
    assert baked.opacity_logits is scene.opacity_logits and baked.sh_dc is scene.sh_dc
    np.testing.assert_allclose(baked.means, scene.means @ linear.T + (1.0, -2.0, 0.5), rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(covariances(baked), linear @ covariances(scene) @ linear.T, rtol=1e-4, atol=1e-5)
    assert list(baked.extras) == ["nx", "label", "ny", "nz"]
    assert [baked.extras[p].dtype for p in ("nx", "ny", "nz")] == [np.float32, np.float64, np.float32]
    np.testing.assert_array_equal(baked.extras["label"], scene.extras["label"])
    normals = np.stack([baked.extras[p] for p in ("nx", "ny", "nz")], axis=1).astype(np.float64)
    old = np.stack([scene.extras[p] for p in ("nx", "ny", "nz")], axis=1).astype(np.float64)
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), np.linalg.norm(old, axis=1), rtol=1e-5)
    assert notes == ([] if np.allclose(linear @ linear.T, 4 * np.eye(3)) else [transform.GENERAL_NOTE])


def test_the_shared_modules_and_the_bake_need_no_torch():
    """Blender's Python has no torch until the engine's dependencies are installed."""
    code = (
        "import sys; sys.modules['torch'] = None\n"
        "import numpy as np\n"
        "from gt2gs_blender.blender import transform\n"
        "from gt2gs_blender.core import rotations\n"
        "from gt2gs_blender.core.scene import inria, ply_write\n"
        "from gt2gs_blender.core.scene.arrays import SplatArrays\n"
        "z = lambda *s: np.zeros(s, np.float32)\n"
        "scene = SplatArrays(z(2, 3), z(2, 4), z(2, 3), z(2), z(2, 3), z(2, 3, 3), {})\n"
        "baked, notes = transform.bake(scene, np.diag([1.0, 2.0, 3.0, 1.0]))\n"
        "assert np.isfinite(baked.quats).all() and notes\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=PACKAGE.parent)
    assert proc.returncode == 0, proc.stderr[-2000:]
