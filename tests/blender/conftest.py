"""Fixtures for the Blender tests: the bpy module, the registered extension, fresh factory settings.

Every test module here starts with ``pytest.importorskip("bpy", exc_type=ModuleNotFoundError)`` and
``pytestmark = pytest.mark.blender``, so the whole folder skips cleanly where bpy is not installed,
while a bpy that is installed but fails to import is an error, not a skip. The extension
is registered once per session from the source tree (as the test runner imports it) and each test
starts from Blender's factory settings with an empty scene, as MolecularNodes' tests do. Installing
and enabling the built extension zip runs in a subprocess (test_extension.py), so that its
``bl_ext.*`` copy never meets the source-tree registration in one process.
"""

from __future__ import annotations

from pathlib import Path

import pytest

SHARED = Path(__file__).resolve().parents[2].parent / "shared"
DONUT = SHARED / "data" / "scenes" / "donut" / "point_cloud.ply"
DONUT_COUNT = 45624


@pytest.fixture(scope="session")
def bpy_module():
    return pytest.importorskip("bpy", exc_type=ModuleNotFoundError)


@pytest.fixture(scope="session")
def extension(bpy_module):
    """The gt2gs_blender package, registered for the session (unregistered at the end)."""
    import gt2gs_blender

    gt2gs_blender.register()
    yield gt2gs_blender
    gt2gs_blender.unregister()


@pytest.fixture
def fresh(bpy_module, extension):
    """Factory settings with an empty scene before the test; bpy for the test to use."""
    bpy_module.ops.wm.read_factory_settings(use_empty=True)
    yield bpy_module
    bpy_module.ops.wm.read_factory_settings(use_empty=True)


@pytest.fixture
def donut() -> Path:
    if not DONUT.is_file():
        pytest.skip(f"shared donut scene not found at {DONUT}")
    return DONUT
