"""Never lose the user's file, in Blender (issue 36): exporting onto the file an object was imported from is
refused unless *Overwrite Imported File* is ticked, an export that cannot be written fails naming the path and
leaves nothing, a named pipe is refused on import instead of blocking Blender, and the batch script follows the
command line's output rules before importing anything."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

bpy = pytest.importorskip("bpy", exc_type=ModuleNotFoundError)
pytest.importorskip("torch", exc_type=ModuleNotFoundError, reason="the scenes and the path rules are the engine's")

from gt2gs_blender.app.cli.demo import torus_scene
from gt2gs_blender.blender import transfer_run
from gt2gs_blender.core.scene.files import read_splats, write_splats

from ..test_bad_paths import ALIASES, SCENES, alias, no_hang, snapshot

pytestmark = pytest.mark.blender


@pytest.fixture
def folder(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """The test's working folder with a small scene in every writable format and a file that is no folder."""
    monkeypatch.chdir(tmp_path)
    scene = torus_scene(n_major=12, n_minor=6)
    for name in SCENES.values():
        write_splats(name, scene)
    Path("texture.png").write_bytes(b"not read: the batch refuses before")
    Path("afile").write_bytes(b"a file, not a folder")
    return tmp_path


def imported(path: str):
    assert bpy.ops.gt2gs.import_ply(filepath=os.path.abspath(path)) == {"FINISHED"}
    return bpy.context.active_object


@pytest.mark.parametrize("kind", ALIASES)
@pytest.mark.parametrize("fmt", sorted(SCENES))
def test_export_onto_the_imported_file_is_refused(fresh, folder, fmt, kind):
    imported(SCENES[fmt])
    target = alias(SCENES[fmt], kind)
    before = snapshot(folder)
    with pytest.raises(RuntimeError, match=r"is your imported original.*Overwrite Imported File"):
        bpy.ops.gt2gs.export_ply(filepath=os.path.abspath(target))
    assert snapshot(folder) == before


def test_export_onto_another_objects_imported_file_is_refused(fresh, folder):
    """Two captures in one .blend: exporting the active one over the other's original is refused too."""
    imported("scene.ply")
    active = imported("scene.spz")
    assert bpy.context.active_object == active
    before = snapshot(folder)
    with pytest.raises(RuntimeError, match=r"scene\.ply: is your imported original, the file 'scene' comes from"):
        bpy.ops.gt2gs.export_ply(filepath=os.path.abspath("scene.ply"))
    assert snapshot(folder) == before


def test_export_onto_the_imported_file_when_asked_to(fresh, folder):
    obj = imported("scene.spz")
    assert bpy.ops.gt2gs.export_ply(filepath=os.path.abspath("scene.spz"), overwrite_source=True) == {"FINISHED"}
    assert len(read_splats("scene.spz")) == len(obj.data.points)


@pytest.mark.parametrize("mode", ["NEW", "IN_PLACE"])
def test_a_transfer_result_is_not_exported_onto_the_file_its_original_was_imported_from(fresh, folder, donut, mode):
    """The artist imports donut.ply, transfers a texture and exports "donut GT²" as donut.ply: refused, the file
    kept byte for byte, unless Overwrite Imported File is ticked."""
    original = folder / "donut.ply"
    shutil.copyfile(donut, original)
    kept = original.read_bytes()
    source = imported(str(original))
    result = transfer_run.apply_result(bpy.context, source, str(folder / "scene.ply"), mode)  # the worker's
    assert bpy.context.active_object == result
    with pytest.raises(RuntimeError, match=r"is your imported original.*Overwrite Imported File") as caught:
        bpy.ops.gt2gs.export_ply(filepath=str(original))
    assert str(original) in str(caught.value) and len(str(caught.value).strip().splitlines()) == 1
    assert original.read_bytes() == kept
    assert bpy.ops.gt2gs.export_ply(filepath=str(original), overwrite_source=True) == {"FINISHED"}
    assert len(read_splats(original)) == len(result.data.points) != len(read_splats(donut))


@pytest.mark.parametrize(
    "target, words",
    [
        ("afile/out.ply", "afile is not a folder"),
        ("no/such/out.ply", "does not exist"),
        ("/proc/gt2gs-out.ply", "takes no new files"),
        ("x" * 300 + ".ply", "too long"),
    ],
    ids=["file-as-folder", "missing-folder", "proc", "long-name"],
)
def test_an_export_that_cannot_be_written_names_the_path_and_leaves_nothing(fresh, folder, target, words):
    imported("scene.ply")
    before = snapshot(folder)
    with pytest.raises(RuntimeError, match=words) as caught:
        bpy.ops.gt2gs.export_ply(filepath=os.path.abspath(target))
    assert os.path.abspath(target) in str(caught.value) and ".tmp" not in str(caught.value)
    assert snapshot(folder) == before


def test_importing_a_named_pipe_is_refused_and_leaves_the_scene(fresh, folder):
    os.mkfifo("pipe.ply")
    with no_hang(), pytest.raises(RuntimeError, match="named pipe"):
        bpy.ops.gt2gs.import_ply(filepath=os.path.abspath("pipe.ply"))
    assert len(bpy.data.objects) == 0


BATCH_INPUTS = {"scene": "scene.ply", "texture": "texture.png"}


@pytest.mark.parametrize("kind", ALIASES)
@pytest.mark.parametrize("which", sorted(BATCH_INPUTS))
def test_batch_refuses_an_output_over_an_input_before_importing(fresh, folder, capsys, which, kind):
    from gt2gs_blender import batch

    out = alias(BATCH_INPUTS[which], kind)
    before = snapshot(folder)
    assert batch.main(["--ply", "scene.ply", "--texture", "texture.png", "--out", out, "--preset", "preview"]) == 1
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1 and f"would overwrite the {which}" in lines[0] and str(Path(out)) in lines[0]
    assert snapshot(folder) == before and len(bpy.data.objects) == 0


@pytest.mark.parametrize(
    "argv, words",
    [
        (["--out", "afile/out.ply"], "afile is not a folder"),
        (["--out", "no/such/out.ply"], "does not exist"),
        (["--out", "out.ply", "--texture", "pipe"], "named pipe"),
    ],
    ids=["file-as-folder", "missing-folder", "pipe-texture"],
)
def test_batch_refuses_bad_paths_before_importing(fresh, folder, capsys, argv, words):
    from gt2gs_blender import batch

    os.mkfifo("pipe")
    given = {"--ply": "scene.ply", "--texture": "texture.png", **dict(zip(argv[::2], argv[1::2]))}
    before = snapshot(folder)
    with no_hang():
        assert batch.main([arg for pair in given.items() for arg in pair]) == 1
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1 and words in lines[0]
    assert snapshot(folder) == before and len(bpy.data.objects) == 0
