"""The library API (``gt2gs_blender.core.api``) and the engine's light part: what Blender imports of the
engine loads without torch."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LIGHT = (
    "gt2gs_blender.core",
    "gt2gs_blender.core.errors",
    "gt2gs_blender.core.raster_rules",
    "gt2gs_blender.core.features.specs",
    "gt2gs_blender.core.progress",
    "gt2gs_blender.core.rotations",
    "gt2gs_blender.core.scene.inria",
    "gt2gs_blender.core.scene.ply",
    "gt2gs_blender.core.scene.ply_write",
    "gt2gs_blender.core.scene.files",
    "gt2gs_blender.core.transfer.config",
    "gt2gs_blender.core.transfer.presets",
    "gt2gs_blender.app.protocol",
    "gt2gs_blender.app.deps",
)
"""Modules Blender's own Python imports (the worker alone loads torch)."""


def test_the_api_gathers_the_engines_own_objects():
    from gt2gs_blender.core import api
    from gt2gs_blender.core.render import render
    from gt2gs_blender.core.transfer.pipeline import transfer

    assert api.render is render and api.transfer is transfer
    assert all(hasattr(api, name) for name in api.__all__)


def test_what_blender_imports_loads_without_torch():
    probe = f"import sys; import {', '.join(LIGHT)}; print('torch' in sys.modules)"
    result = subprocess.run([sys.executable, "-c", probe], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "False"


def test_the_readme_example_runs(tmp_path):
    """The README's Python API example, on a tiny generated scene and texture."""
    from gt2gs_blender.app.cli.demo import stripes_texture, torus_scene
    from gt2gs_blender.core.api import preset, read_scene, transfer, write_splats

    write_splats(tmp_path / "point_cloud.ply", torus_scene(n_major=24, n_minor=12))
    scene = read_scene(tmp_path / "point_cloud.ply")
    config = preset("preview", angle=30.0, stylise_steps=2, correct_steps=2, resolution=32, evaluate=False)
    result = transfer(scene, stripes_texture(64), views=3, config=config)
    assert write_splats(tmp_path / "stylised.spz", result.scene) == []
    assert len(read_scene(tmp_path / "stylised.spz")) == len(result.scene) >= len(scene)
