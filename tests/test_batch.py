"""The batch on a real Dask cluster: a scheduler and two worker processes on 127.0.0.1 (started once for the
module; the bad-texture test runs on the command's own local cluster). Its results equal the single-job
command's; a job whose worker is killed runs again; a bad texture fails alone, with its one-line error in the
summary; Ctrl-C leaves no half files, and ``--resume`` runs only the jobs that did not finish. Jobs are the
``preview`` preset at 4 views, on the donut and a small torus."""

from __future__ import annotations

import json
import logging
import os
import signal
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
from distributed import Client, LocalCluster

from gt2gs_blender.app.batch.cluster import TOPIC, run_batch
from gt2gs_blender.app.batch.manifest import read_manifest
from gt2gs_blender.app.batch.outputs import finished, settings_hashes
from gt2gs_blender.app.cli import main as cli
from gt2gs_blender.app.cli.demo import torus_scene
from gt2gs_blender.core.scene.ply import read_ply
from gt2gs_blender.core.scene.ply_write import write_ply

from .conftest import SHARED

REPO = Path(__file__).resolve().parents[1]
DONUT = SHARED / "data" / "scenes" / "donut" / "point_cloud.ply"
BRICK = SHARED / "data" / "textures" / "brick_wall.jpg"
GUITAR = SHARED / "data" / "scenes" / "captures" / "guitar.compressed.ply"
SMALL = "preset = 'preview'\n[settings]\nn_views = 4\n"
"""Every job's settings: the preview preset at 4 views (the smallest run that still restyles the scene)."""

pytestmark = pytest.mark.skipif(not DONUT.is_file(), reason=f"the shared donut is not at {DONUT}")


@pytest.fixture(scope="module")
def cluster():
    """A Dask scheduler and two single-thread worker processes on 127.0.0.1, and a client of it."""
    with (
        LocalCluster(
            n_workers=2,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address=":0",
            silence_logs=logging.ERROR,
        ) as local,
        Client(local) as client,
    ):
        yield client


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> dict[str, Path]:
    """Two scenes (the donut, a 1,200-splat torus) and two textures (bricks, generated stripes)."""
    folder = tmp_path_factory.mktemp("inputs")
    write_ply(folder / "torus.ply", torus_scene(n_major=40, n_minor=30))
    y, x = np.mgrid[0:128, 0:128]
    stripes = ((((x + y) // 8) % 2) * 200 + 30).astype(np.uint8)
    cv2.imwrite(str(folder / "stripes.png"), np.stack([stripes, stripes // 2, 255 - stripes], axis=-1))
    return {"donut": DONUT, "torus": folder / "torus.ply", "brick": BRICK, "stripes": folder / "stripes.png"}


def batch(client: Client, manifest: Path, out: Path, **options) -> list:
    """Run the manifest on the test cluster with one thread per job; the summary's rows."""
    return run_batch(manifest, out, scheduler=client.scheduler.address, threads=1, **options).rows


def test_a_2x2_batch_equals_the_jobs_run_one_by_one(cluster, inputs, tmp_path, capsys):
    manifest = tmp_path / "jobs.toml"
    manifest.write_text(
        SMALL + f"[[product]]\nscene = ['{inputs['donut']}', '{inputs['torus']}']\n"
        f"texture = ['{inputs['brick']}', '{inputs['stripes']}']\n"
    )
    rows = batch(cluster, manifest, tmp_path / "out")
    assert [(r.status, r.attempts) for r in rows] == [("done", 1)] * 4
    lines = capsys.readouterr().out.splitlines()
    assert (
        sum(line.startswith("start ") for line in lines) == 4 and sum(line.startswith("done ") for line in lines) == 4
    )
    for row in rows:
        alone = tmp_path / f"{row.job.name}.ply"
        one = ["--preset", "preview", "--views", "4", "--threads", "1"]
        assert cli.main(["transfer", str(row.job.scene), str(row.job.texture), "-o", str(alone), *one]) == 0
        expected, got = read_ply(alone).tensors(), read_ply(tmp_path / "out" / row.job.name / row.job.output).tensors()
        for name, values in expected.items():
            assert got[name].shape == values.shape
            assert np.abs(got[name].numpy() - values.numpy()).max(initial=0.0) <= 1e-6, (row.job.name, name)
        report = json.loads((tmp_path / "out" / row.job.name / "report.json").read_text())
        assert report["n_gaussians"] == len(read_ply(alone)) and report["batch"]["job"] == row.job.name
        assert (tmp_path / "out" / row.job.name / "before_after.png").is_file()
    original = read_ply(inputs["torus"]).sh_dc
    stylised = read_ply(tmp_path / "out" / rows[2].job.name / rows[2].job.output).sh_dc
    assert float((stylised.mean(0) - original.mean(0)).abs().max()) > 1e-3  # the run restyled the torus
    sheet = cv2.imread(str(tmp_path / "out" / "contact_sheet.png"))
    assert sheet.shape[0] > 256 and sheet.shape[1] == 4 * 256
    summary = (tmp_path / "out" / "summary.csv").read_text().splitlines()
    assert len(summary) == 5 and summary[0].startswith("job,status,attempts")


def test_what_a_jobs_format_drops_is_the_batchs_own_warning(cluster, inputs, tmp_path):
    """A warning raised on a worker (SPZ clips the guitar's finest splats' log scales) comes back with the job's
    outcome and is raised by the batch, naming the job, instead of printed raw by the worker process."""
    manifest = tmp_path / "jobs.csv"
    manifest.write_text(f"scene,texture,preset,n_views,output\n{GUITAR},{inputs['stripes']},preview,4,g.spz\n")
    with pytest.warns(UserWarning, match=r"^g: .*g\.spz: spz clips") as raised:
        (row,) = batch(cluster, manifest, tmp_path / "out")
    assert row.status == "done" and (tmp_path / "out" / "g" / "g.spz").is_file()
    result = tmp_path / "out" / "g" / "g.spz"
    assert all(str(w.message).startswith(f"g: {result}: spz clips") for w in raised)  # each note once, the job's


def test_a_job_whose_worker_is_killed_runs_again(cluster, inputs, tmp_path):
    killed: list[int] = []

    def kill_first(event: tuple) -> None:
        message = event[1]
        if not killed:
            killed.append(message["pid"])
            os.kill(message["pid"], signal.SIGKILL)

    cluster.subscribe_topic(TOPIC, kill_first)
    try:
        manifest = tmp_path / "jobs.csv"
        manifest.write_text(f"scene,texture,preset,n_views\n{inputs['torus']},{inputs['brick']},preview,4\n")
        (row,) = batch(cluster, manifest, tmp_path / "out")
    finally:
        cluster.unsubscribe_topic(TOPIC)
    assert killed and (row.status, row.attempts) == ("done", 2)
    assert row.report["batch"]["worker"] and (tmp_path / "out" / row.job.name / row.job.output).is_file()
    assert not list((tmp_path / "out").rglob(".*.tmp"))


def test_a_bad_texture_fails_alone_with_its_one_line_error(inputs, tmp_path, capsys):
    """On the command's own local cluster (two worker processes it starts and stops)."""
    bad = tmp_path / "bad.png"
    bad.write_bytes(b"not an image")
    manifest = tmp_path / "jobs.csv"
    manifest.write_text(
        f"scene,texture,preset,n_views\n{inputs['torus']},{inputs['brick']},preview,4\n"
        f"{inputs['torus']},{bad},preview,4\n"
    )
    out = tmp_path / "out"
    assert cli.main(["batch", str(manifest), "--out", str(out), "--workers", "2", "--threads", "1"]) == 2
    shown, err = capsys.readouterr()
    assert shown.startswith("running on a local Dask cluster: 2 workers, 2 jobs at once")
    err = err.strip().splitlines()
    assert err == [f"gt2gs: error: 1 of 2 jobs failed; see {out / 'summary.md'}"]
    table = (out / "summary.md").read_text()
    (failed,) = [line for line in table.splitlines() if "| failed |" in line]
    assert failed.startswith("| torus-bad |") and f"{bad}: not an image file" in failed
    assert "| torus-brick_wall | done | 1 |" in table
    assert not (out / "torus-bad").exists() and (out / "torus-brick_wall" / "torus-brick_wall.ply").is_file()


def test_resume_after_ctrl_c_runs_only_the_jobs_that_did_not_finish(cluster, inputs, tmp_path):
    """Ctrl-C (SIGINT to the batch command) once a job is done: the others stop and leave nothing; --resume then
    runs only those. Five jobs on two workers, each long enough (400 steps) that some are still to run when the
    signal lands, however slowly the test reads the command's output on a busy machine (at the preview's 40 steps,
    warm workers finished the whole batch before the signal)."""
    manifest = tmp_path / "jobs.toml"
    angles = "[0, 30, 60, 90, 120]"
    manifest.write_text(
        SMALL
        + "stylise_steps = 400\n"
        + f"[[product]]\nscene = '{inputs['torus']}'\ntexture = '{inputs['stripes']}'\nangle = {angles}\n"
    )
    out = tmp_path / "out"
    command = [sys.executable, "-m", "gt2gs_blender", "batch", str(manifest), "--out", str(out), "--threads", "1"]
    command += ["--scheduler", cluster.scheduler.address]
    # as a terminal starts it, Ctrl-C at its default: a suite started in the background by a shell without job
    # control (`make test &`) runs with SIGINT ignored, which the command would inherit, and Python never turns an
    # ignored SIGINT into KeyboardInterrupt
    with subprocess.Popen(
        command,
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    ) as batch_cmd:
        for line in batch_cmd.stdout:
            if line.startswith("done "):
                batch_cmd.send_signal(signal.SIGINT)
                break
        shown, err = batch_cmd.communicate(timeout=120)
    assert batch_cmd.returncode == 130 and "interrupted: cancelling the batch" in shown, err
    assert err.strip().splitlines()[-1] == "gt2gs: error: interrupted"
    first = {
        line.split(" | ")[0][2:]: line.split(" | ")[1]
        for line in (out / "summary.md").read_text().splitlines()
        if line.startswith("| torus")
    }
    done = sorted(name for name, status in first.items() if status == "done")
    assert done and "cancelled" in first.values()
    assert sorted(p.name for p in out.iterdir() if p.is_dir()) == done  # no half folders, no temp files
    assert not list(out.rglob(".*.tmp"))
    kept = {name: (out / name / f"{name}.ply").stat().st_mtime_ns for name in done}

    rows = batch(cluster, manifest, out, resume=True)
    assert {r.job.name: r.status for r in rows} == {name: "kept" if name in done else "done" for name in first}
    assert {name: (out / name / f"{name}.ply").stat().st_mtime_ns for name in done} == kept
    jobs = read_manifest(manifest)
    keys = settings_hashes(jobs)
    assert all(finished(out, job, key) is not None for job, key in zip(jobs, keys))
    assert finished(out, jobs[0], keys[1]) is None  # another job's settings: not this folder's result
