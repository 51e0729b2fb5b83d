"""Blender's batch script reads the same manifest as the command line's ``batch``: one folder per job with its
result and report, the summary table, a bad job failing alone, and ``--resume``."""

from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip("bpy", exc_type=ModuleNotFoundError)

from gt2gs_blender.app.images import write_png
from gt2gs_blender.core.scene.ply import read_ply_arrays
from gt2gs_blender.core.scene.ply_write import write_ply

from ..worker_tools import blob_splats, stripes

pytestmark = pytest.mark.blender

SMALL = "preview,2,6,48,4"
"""preset, n_views, stylise_steps, resolution, n_angles: a run of seconds."""


def test_the_batch_script_runs_a_manifest(fresh, tmp_path, capsys):
    from gt2gs_blender import batch

    write_ply(tmp_path / "blob.ply", blob_splats(600))
    write_png(tmp_path / "stripes.png", (stripes() * 255).astype(np.uint8))
    (tmp_path / "bad.png").write_bytes(b"not an image")
    manifest = tmp_path / "jobs.csv"
    manifest.write_text(
        "scene,texture,angle,preset,n_views,stylise_steps,resolution,n_angles\n"
        f"blob.ply,stripes.png,0,{SMALL}\nblob.ply,stripes.png,90,{SMALL}\nblob.ply,bad.png,0,{SMALL}\n"
    )
    out = tmp_path / "out"
    assert batch.main(["--manifest", str(manifest), "--out", str(out)]) == 1
    captured = capsys.readouterr()
    assert captured.err.splitlines() == [f"gt2gs: error: 1 of 3 jobs failed; see {out / 'summary.md'}"]
    said = [line for line in captured.out.splitlines() if "bad.png" in line]
    assert len(said) == 1 and said[0].startswith("gt2gs: failed blob-bad-angle0: ")  # not Blender's echo too
    for name in ("blob-stripes-angle0", "blob-stripes-angle90"):
        report = json.loads((out / name / "report.json").read_text())
        assert report["batch"]["job"] == name and len(report["batch"]["settings_hash"]) == 64
        assert len(read_ply_arrays(out / name / f"{name}.ply")) == report["n_gaussians"]
        assert report["config"]["n_views"] == 2 and report["config"]["stylise_steps"] == 6
    assert json.loads((out / "blob-stripes-angle90" / "report.json").read_text())["config"]["angle"] == 90.0
    assert not (out / "blob-bad-angle0").exists()
    table = (out / "summary.md").read_text()
    assert "| blob-bad-angle0 | failed | 1 |" in table and "bad.png" in table

    mtime = (out / "blob-stripes-angle0" / "blob-stripes-angle0.ply").stat().st_mtime_ns
    assert batch.main(["--manifest", str(manifest), "--out", str(out), "--resume"]) == 1
    statuses = [
        line.split(" | ")[1] for line in (out / "summary.md").read_text().splitlines() if line.startswith("| blob")
    ]
    assert statuses == ["kept", "kept", "failed"]
    assert (out / "blob-stripes-angle0" / "blob-stripes-angle0.ply").stat().st_mtime_ns == mtime
