"""Blender import and export of every splat format, with the real bpy: each import matches the PLY's, each
export writes the format its name or File Format says."""

from __future__ import annotations

import re

import numpy as np
import pytest

bpy = pytest.importorskip("bpy", exc_type=ModuleNotFoundError)

from gt2gs_blender.core.scene.files import FORMATS, READ_EXTENSIONS, WRITERS, detect_format, read_splats

pytestmark = pytest.mark.blender
DONUT_COUNT = 45624


def imported(path) -> bpy.types.Object:
    """The object ``gt2gs.import_ply`` makes of a file."""
    assert bpy.ops.gt2gs.import_ply(filepath=str(path)) == {"FINISHED"}
    return bpy.context.active_object


def positions(obj) -> np.ndarray:
    """The point positions of a point-cloud object."""
    values = np.empty(len(obj.data.points) * 3, np.float32)
    obj.data.points.foreach_get("co", values)
    return values.reshape(-1, 3)


@pytest.mark.parametrize("fmt", ["compressed-ply", "sog", "spz", "splat"])
def test_every_format_imports_like_the_ply(fresh, donut_files, fmt):
    reference = read_splats(donut_files["ply"]).means
    obj = imported(donut_files[fmt])
    got = positions(obj)
    assert len(got) == DONUT_COUNT and obj.name == "donut"
    assert np.allclose(np.sort(got, axis=0), np.sort(reference, axis=0), atol=2e-3)  # order-free, within quantisation


@pytest.mark.parametrize("fmt", sorted(WRITERS))
def test_export_writes_the_format_the_file_name_says(fresh, donut_files, tmp_path, fmt):
    imported(donut_files["ply"])
    out = tmp_path / f"out{FORMATS[fmt].extensions[0]}"
    assert bpy.ops.gt2gs.export_ply(filepath=str(out)) == {"FINISHED"}
    assert detect_format(out) == fmt and len(read_splats(out)) == DONUT_COUNT


def test_export_file_format_overrides_the_name_and_sog_is_refused(fresh, donut_files, tmp_path):
    imported(donut_files["ply"])
    assert bpy.ops.gt2gs.export_ply(filepath=str(tmp_path / "named.ply"), file_format="spz") == {"FINISHED"}
    assert detect_format(tmp_path / "named.ply") == "spz"
    with pytest.raises(RuntimeError, match="PlayCanvas SOG is read only here"):
        bpy.ops.gt2gs.export_ply(filepath=str(tmp_path / "out.sog"))
    assert not (tmp_path / "out.sog").exists()


def test_drag_and_drop_and_the_file_browser_offer_every_format(fresh):
    handler = bpy.types.GT2GS_FH_ply
    assert set(handler.bl_file_extensions.split(";")) == set(READ_EXTENSIONS) == {".ply", ".sog", ".splat", ".spz"}


def test_a_broken_file_of_any_format_is_reported_and_creates_nothing(fresh, donut_files, tmp_path):
    pytest.importorskip("torch", exc_type=ModuleNotFoundError, reason="the broken files are made by the engine's tests")
    from ..test_bad_inputs import broken_splat_files

    counts = {name: len(getattr(bpy.data, name)) for name in ("objects", "pointclouds", "materials", "images")}
    for name, path in broken_splat_files(tmp_path / "broken", donut_files).items():
        with pytest.raises(RuntimeError, match=re.escape(str(path))):
            bpy.ops.gt2gs.import_ply(filepath=str(path))
        assert {n: len(getattr(bpy.data, n)) for n in counts} == counts, name
