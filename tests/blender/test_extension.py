"""Build, validate and install the extension with Blender's own tool, then enable it as users do.

``blender_ext.py`` (inside the bpy wheel) builds the zip from gt2gs_blender/ by its manifest,
validates it and installs it into a local repository; a fresh Python process then adds that
repository to Blender's preferences, enables ``bl_ext.<repo>.gt2gs_blender``, uses the import
operator and disables the extension again.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
import zipfile
from pathlib import Path

import pytest

bpy = pytest.importorskip("bpy", exc_type=ModuleNotFoundError)

from .conftest import DONUT, DONUT_COUNT

pytestmark = pytest.mark.blender

ROOT = Path(__file__).resolve().parents[2]
SOURCE = ROOT / "gt2gs_blender"
BLENDER_VERSION = bpy.app.version_string.split()[0]


def blender_ext() -> Path:
    tool = Path(bpy.utils.system_resource("SCRIPTS")) / "addons_core" / "bl_pkg" / "cli" / "blender_ext.py"
    if not tool.is_file():
        pytest.skip(f"Blender's extension tool not found at {tool}")
    return tool


def run_tool(*args: str) -> subprocess.CompletedProcess:
    result = subprocess.run([sys.executable, str(blender_ext()), *args], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, f"blender_ext {args[0]} failed:\n{result.stdout}\n{result.stderr}"
    return result


@pytest.fixture(scope="module")
def built_zip(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("build")
    run_tool("build", "--source-dir", str(SOURCE), "--output-dir", str(out))
    (zip_path,) = out.glob("*.zip")
    return zip_path


def test_the_readme_build_works_on_a_fresh_clone(tmp_path):
    """`make build` (the README's command) in a copy of the tree without dist/ (the issue's fresh clone), on
    this bpy's Python: it makes the folder Blender's tool refuses to do without."""
    for name in ("Makefile", "requirements.txt", "requirements-py313.txt"):
        (tmp_path / name).write_bytes((ROOT / name).read_bytes())
    (tmp_path / "gt2gs_blender").symlink_to(SOURCE, target_is_directory=True)
    result = subprocess.run(
        ["make", "-s", "build", "STAMP=", f"PY={sys.executable}"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=180,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    assert [p.name for p in (tmp_path / "dist").iterdir()] == ["gt2gs_blender-0.1.0.zip"]


def test_build_ships_the_package_and_nothing_else(built_zip):
    names = zipfile.ZipFile(built_zip).namelist()
    assert built_zip.name == "gt2gs_blender-0.1.0.zip"
    for required in (
        "blender_manifest.toml",
        "__init__.py",
        "operators/io_import.py",
        "operators/io_export.py",
        "operators/transfer.py",
        "app/worker.py",
        "batch.py",
        "panels/sidebar.py",
        "blender/splats.py",
        "core/scene/ply.py",
        "core/render/csrc/raster_cpu.cpp",
    ):  # the C++ source is compiled at run time
        assert required in names, required
    leaked = [
        n
        for n in names
        if "__pycache__" in n or n.endswith((".pyc", ".o", ".so")) or any(part.startswith(".") for part in n.split("/"))
    ]
    assert not leaked


def test_validate_and_install_then_enable_in_blender(built_zip, tmp_path):
    run_tool("validate", str(built_zip))
    repo = tmp_path / "repo"
    repo.mkdir()
    run_tool("install-files", "--local-dir", str(repo), "--blender-version", BLENDER_VERSION, str(built_zip))
    assert (repo / "gt2gs_blender" / "blender_manifest.toml").is_file()
    assert (repo / "gt2gs_blender" / "core" / "render" / "csrc" / "raster_cpu.cpp").is_file()

    script = textwrap.dedent(f"""
        import json, sys
        import bpy, addon_utils
        bpy.ops.wm.read_factory_settings(use_empty=True)
        bpy.context.preferences.extensions.repos.new(
            name="gt2gs_test", module="gt2gs_test", custom_directory={str(repo)!r}, source="USER")
        module = "bl_ext.gt2gs_test.gt2gs_blender"
        report = {{}}
        addon_utils.enable(module, default_set=True, handle_error=None)
        report["enabled"] = module in bpy.context.preferences.addons
        report["loaded_from"] = sys.modules[module].__file__
        classes = ("GT2GS_OT_import_ply", "GT2GS_OT_export_ply", "GT2GS_FH_ply", "VIEW3D_PT_gt2gs_splat",
                   "GT2GS_OT_transfer_texture", "GT2GS_OT_preview_orientation", "VIEW3D_PT_gt2gs_transfer")
        report["operators"] = [hasattr(bpy.types, c) for c in classes]
        prefs = bpy.context.preferences.addons[module].preferences
        report["preferences"] = [prefs.device, prefs.threads]
        prefs.threads = 3  # the worker's CPU threads reach the job's config
        run = sys.modules[module + ".blender.transfer_run"]
        report["job_threads"] = run.config_overrides(bpy.context, {{}})[1].get("threads")
        prefs.threads = 0
        report["job_threads_default"] = run.config_overrides(bpy.context, {{}})[1].get("threads")
        donut = {str(DONUT)!r}
        if {DONUT.is_file()!r}:
            bpy.ops.gt2gs.import_ply(filepath=donut)
            obj = bpy.context.active_object
            report["imported"] = [obj.type, len(obj.data.points)]
            report["engine_module"] = [m for m in sys.modules if m.endswith("gt2gs_blender.core.scene.ply")]
            # a "texture" that is no image is refused before any worker starts
            try:
                bpy.ops.gt2gs.preview_orientation(texture_path=donut, n_views=2)
            except RuntimeError as exc:
                report["texture_error"] = str(exc)
        # the worker's Python runs the installed copy (its folder on the worker's PYTHONPATH): the machine
        # check (a real run would also compile the installed copy's C++ rasterizer, minutes on a busy machine)
        machine = sys.modules[module + ".blender.machine"]
        info, error = machine.probe({{"backend": "torch"}}, None)
        report["probe"] = [error, sorted(info or {{}})]
        addon_utils.disable(module, default_set=True, handle_error=None)
        report["disabled"] = module not in bpy.context.preferences.addons
        report["after_disable"] = [hasattr(bpy.types, c) for c in ("GT2GS_OT_import_ply", "VIEW3D_PT_gt2gs_splat")]
        print("REPORT " + json.dumps(report))
    """)
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "user"))
    env.pop("PYTHONPATH", None)  # the installed copy, not the source tree, must provide the extension
    result = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=120, cwd=tmp_path, env=env
    )
    lines = [line for line in result.stdout.splitlines() if line.startswith("REPORT ")]
    assert result.returncode == 0 and lines, f"{result.stdout}\n{result.stderr}"
    report = json.loads(lines[-1][len("REPORT ") :])

    assert report["enabled"]
    assert Path(report["loaded_from"]).resolve() == (repo / "gt2gs_blender" / "__init__.py").resolve()
    assert report["operators"] == [True] * 7 and report["preferences"] == ["auto", 0]
    assert report["job_threads"] == 3 and report["job_threads_default"] == 0
    if DONUT.is_file():
        assert report["imported"] == ["POINTCLOUD", DONUT_COUNT]
        assert report["engine_module"] == ["bl_ext.gt2gs_test.gt2gs_blender.core.scene.ply"]
        expected = f"the texture {DONUT} is not an image file: choose a PNG, JPEG, TIFF, BMP, WebP or EXR picture"
        assert report["texture_error"].strip() == f"Error: {expected}"
    error, keys = report["probe"]
    assert error is None and {"weights", "rasterizer", "compiler", "cuda", "kernel_cache"} <= set(keys)
    assert report["disabled"]
    assert report["after_disable"] == [False, False]
