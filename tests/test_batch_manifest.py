"""A batch's manifest (CSV and TOML, a product of lists), its mistakes as one line naming the file and the row,
the jobs' folder names, and the settings hash ``--resume`` compares."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from gt2gs_blender.app.batch.manifest import read_manifest
from gt2gs_blender.app.batch.outputs import settings_hashes
from gt2gs_blender.core.errors import InputFileError


def write(folder: Path, name: str, text: str) -> Path:
    path = folder / name
    path.write_text(text)
    return path


def one_line_error(path: Path, *words: str) -> None:
    with pytest.raises(InputFileError) as caught:
        read_manifest(path)
    message = str(caught.value)
    assert "\n" not in message and message.startswith(f"{path}: "), message
    for word in words:
        assert word in message, message


def test_csv_rows_are_jobs_with_typed_settings_relative_to_the_manifest(tmp_path):
    manifest = write(
        tmp_path,
        "jobs.csv",
        "scene,texture,preset,angle,n_views,gt2,background,output\n"
        'scenes/a.ply,tex/brick.jpg,preview,30,4,false,"1,0.5,0",first.spz\n'
        "scenes/a.ply,tex/brick.jpg,,,,,,\n",
    )
    first, second = read_manifest(manifest)
    assert first.scene == tmp_path / "scenes" / "a.ply" and first.texture == tmp_path / "tex" / "brick.jpg"
    assert first.settings == {"angle": 30.0, "n_views": 4, "gt2": False, "background": (1.0, 0.5, 0.0)}
    assert (first.preset, first.output, first.name) == ("preview", "first.spz", "first")
    assert type(first.settings["n_views"]) is int and type(first.settings["angle"]) is float
    assert (second.preset, second.settings) == ("fast", {})  # empty cells keep the preset's values
    assert second.name == "a-brick-presetfast" and second.output == "a-brick-presetfast.ply"
    assert first.config().n_views == 4 and second.config().n_views == 16


def test_toml_product_is_every_combination_with_the_common_settings(tmp_path):
    manifest = write(
        tmp_path,
        "jobs.toml",
        'preset = "preview"\n[settings]\nn_views = 4\n'
        '[[product]]\nscene = ["x/point_cloud.ply", "y/point_cloud.ply"]\ntexture = ["brick.jpg", "cells.png"]\n'
        "angle = [0, 45]\n"
        '[[job]]\nscene = "x/point_cloud.ply"\ntexture = "brick.jpg"\nn_views = 8\noutput = "eight.ply"\n',
    )
    jobs = read_manifest(manifest)
    assert len(jobs) == 9 and jobs[0].where == "[[job]] 1" and jobs[0].settings["n_views"] == 8
    product = jobs[1:]
    assert [(j.scene.parent.name, j.texture.stem, j.settings["angle"]) for j in product[:3]] == [
        ("x", "brick", 0.0),
        ("x", "brick", 45.0),
        ("x", "cells", 0.0),
    ]
    assert all(j.preset == "preview" and j.settings["n_views"] == 4 for j in product)
    # scenes with one file name are told apart by their folders; the varying settings name the folder
    assert product[0].name == "x_point_cloud-brick-angle0-n_views4"
    assert len({j.name for j in jobs}) == 9


@pytest.mark.parametrize(
    ("text", "words"),
    [
        ("scene\na.ply\n", ["texture"]),
        ("scene,texture,n_veiws\na.ply,b.jpg,3\n", ["n_veiws", "did you mean n_views?"]),
        ("scene,texture,n_views\na.ply,b.jpg,many\n", ["row 2", "n_views must be a whole number", "'many'"]),
        ("scene,texture,n_views\na.ply,b.jpg,3\na.ply,b.jpg,0\n", ["row 3", "n_views"]),
        ("scene,texture,gt2\na.ply,b.jpg,maybe\n", ["row 2", "gt2 must be true or false"]),
        ("scene,texture,preset\na.ply,b.jpg,slow\n", ["row 2", "unknown preset 'slow'"]),
        ("scene,texture,output\na.ply,b.jpg,sub/c.ply\n", ["row 2", "without a folder"]),
        ("scene,texture,output\na.ply,b.jpg,c.obj\n", ["row 2", "must end in one of"]),
        ("scene,texture,threads\na.ply,b.jpg,2\n", ["threads is the batch's", "--threads"]),
        ("scene,texture\na.ply,b.jpg\na.ply,b.jpg\n", ["row 2 and row 3 are the same job"]),
        ("scene,texture\na.ply,b.jpg,extra\n", ["row 2", "3 cells under a header of 2"]),
        ("scene,texture\n", ["no jobs"]),
    ],
)
def test_csv_mistakes_are_one_line_naming_the_manifest_and_row(tmp_path, text, words):
    one_line_error(write(tmp_path, "jobs.csv", text), *words)


@pytest.mark.parametrize(
    ("text", "words"),
    [
        ("[[job]]\nscene = 'a.ply'\n", ["[[job]] 1", "no texture"]),
        ("[[job]\n", ["not valid TOML"]),
        ("jobs = 1\n", ["unknown key(s) jobs"]),
        ("[[product]]\nscene = ['a.ply']\ntexture = []\n", ["[[product]] 1", "texture is empty"]),
        ("[[product]]\nscene = ['a.ply']\ntexture = 'b.jpg'\noutput = 'c.ply'\n", ["give no output"]),
        ("[settings]\nresolution = 2.5\n[[job]]\nscene = 'a.ply'\ntexture = 'b.jpg'\n", ["resolution"]),
    ],
)
def test_toml_mistakes_are_one_line_naming_the_manifest_and_table(tmp_path, text, words):
    one_line_error(write(tmp_path, "jobs.toml", text), *words)


def test_a_manifest_is_csv_or_toml(tmp_path):
    one_line_error(write(tmp_path, "jobs.json", "{}"), ".csv or a .toml")


def test_the_settings_hash_follows_what_the_job_makes(tmp_path):
    """Inputs' contents and the settings that shape the result change it; where the job runs does not."""
    (tmp_path / "a.ply").write_bytes(b"scene")
    (tmp_path / "b.jpg").write_bytes(b"texture")

    def key(**settings: object) -> str:
        columns = {"scene": "a.ply", "texture": "b.jpg", "output": "r.ply", **settings}
        manifest = write(tmp_path, "jobs.csv", ",".join(columns) + "\n" + ",".join(map(str, columns.values())))
        return settings_hashes(read_manifest(manifest))[0]

    base = key(device="cpu")
    assert len(base) == 64 and key(device="auto", backend="torch") == base
    assert key(angle=30) != base and key(preset="preview") != base and key(output="s.ply") != base
    (tmp_path / "b.jpg").write_bytes(b"another texture")
    assert key(device="cpu") != base  # the texture's content, not only its name


def test_blenders_batch_script_reads_manifests_without_torch_dask_or_opencv():
    """Blender's Python has none of them until the engine's dependencies are installed (and never dask)."""
    code = (
        "import sys\n"
        "for name in ('torch', 'dask', 'distributed', 'cv2'): sys.modules[name] = None\n"
        "from gt2gs_blender.app.batch import manifest, outputs, summary\n"
    )
    root = Path(__file__).resolve().parents[1]
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=root)
    assert proc.returncode == 0, proc.stderr[-2000:]
