"""The worker process and its Blender-side handle (bpy-free): events, outputs, cancel, crash, bad input."""

from __future__ import annotations

import json
import os
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from gt2gs_blender.app import deps
from gt2gs_blender.app.images import write_png
from gt2gs_blender.app.protocol import EXIT_INPUT, EXIT_MEMORY, JobSpec
from gt2gs_blender.blender.job import CANCELLED, DONE, ERROR, Job
from gt2gs_blender.core.cameras.cameras_json import save_cameras_json
from gt2gs_blender.core.errors import MEMORY_ADVICE
from gt2gs_blender.core.scene.ply import read_ply_arrays
from gt2gs_blender.core.scene.ply_write import write_ply

from .test_bad_inputs import BLIND_CAMERAS
from .test_transfer import blob_scene
from .worker_tools import OUT_OF_MEMORY, address_space_cap, colours_differ, needs_prlimit, stripes

ROOT = Path(__file__).resolve().parents[1]
TINY = dict(
    resolution=48,
    n_views=3,
    stylise_steps=6,
    n_scales=2,
    n_angles=4,
    texture_height=96,
    evaluate=False,
    preview_every=2,
)


def job_with_inputs() -> Job:
    """A new job whose inputs (a small scene and a stripe texture) are in its folder (bench/latency.py uses it too)."""
    job = Job()
    write_ply(job.path("input.ply"), blob_scene(600))
    write_png(job.path("texture.png"), (stripes() * 255).astype(np.uint8))
    return job


@pytest.fixture
def job(tmp_path):
    """A job with its inputs written; cleaned up afterwards."""
    job = job_with_inputs()
    yield job
    job.cleanup()
    assert not job.folder.exists()


def transfer_spec(tmp_path, **config) -> dict:
    return {
        "kind": "transfer",
        "input": "input.ply",
        "texture": "texture.png",
        "output": "out.ply",
        "report": "report.json",
        "views": 3,
        "preset": "preview",
        "config": {**TINY, "cache_dir": str(tmp_path / "banks"), **config},
    }


def test_the_job_file_round_trips_through_the_protocol(job, tmp_path):
    """Blender's side writes the job file with ``JobSpec`` (``Job.start``) and the worker reads it back with
    ``JobSpec.load``: the same job, its relative paths taken from the job's folder, the cancel file and the
    preview folder added by the job."""
    spec = JobSpec(
        kind="preview",
        input=Path("input.ply"),
        texture=tmp_path / "photo.png",
        output=Path("orientation.png"),
        views=Path("cameras.json"),
        preset="preview",
        config={"angle": 30.0, "background": [0.0, 0.5, 1.0]},
        region=Path("region.npy"),
        report=Path("report.json"),
        preview_size=128,
        input_name="object 'Donut'",
        views_name="the scene's cameras",
    )
    job.start(spec)
    job.cancel()
    loaded = JobSpec.load(job.path("job.json"))
    folder = job.folder
    assert loaded == JobSpec(
        kind="preview",
        input=folder / "input.ply",
        texture=tmp_path / "photo.png",
        output=folder / "orientation.png",
        views=folder / "cameras.json",
        preset="preview",
        config={"angle": 30.0, "background": [0.0, 0.5, 1.0]},
        region=folder / "region.npy",
        report=folder / "report.json",
        preview_dir=folder / "previews",
        cancel_file=folder / "cancel",
        preview_size=128,
        input_name="object 'Donut'",
        views_name="the scene's cameras",
    )
    assert JobSpec.load(job.path("job.json")).to_dict() == loaded.to_dict()


def wait_for(job: Job, condition, timeout: float = 120.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        status = job.poll()
        if condition(status):
            return status
        time.sleep(0.05)
    raise AssertionError(f"timed out; status {job.status}, stderr {job.stderr_tail()}")


def test_transfer_job_streams_progress_and_writes_the_result(job, tmp_path):
    job.start(JobSpec.from_dict(transfer_spec(tmp_path)))
    fractions, stages = [], []
    while not job.poll().finished:
        fractions.append(job.status.fraction)
        stages.append(job.status.stage)
        time.sleep(0.05)
    status = job.status
    assert status.state == DONE, (status, job.stderr_tail())
    assert fractions == sorted(fractions) and status.fraction == 1.0
    assert {"prepare", "bank", "stylise"} <= set(stages)
    assert status.preview is not None and Path(status.preview).parent == job.path("previews")
    assert Path(status.preview).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert status.report["n_views"] == 3 and status.report["config"]["stylise_steps"] == 6
    original, result = read_ply_arrays(job.path("input.ply")), read_ply_arrays(status.output)
    assert colours_differ(result.sh_dc, original.sh_dc)
    assert not list(job.folder.rglob("*.tmp"))


@pytest.mark.slow
def test_fast_transfer_without_a_compiler_runs_the_numba_kernel(job, tmp_path):
    """No C++ compiler (CXX and PATH point nowhere) and nothing compiled before: the worker JIT-compiles the
    numba kernel as the visible compile stage, then a whole ``fast`` transfer runs on it, not on torch."""
    pytest.importorskip("numba")
    nowhere = tmp_path / "no-bin"
    nowhere.mkdir()
    job.env.pop("NUMBA_CACHE_DIR", None)
    job.env.update(CXX=str(nowhere / "c++"), PATH=str(nowhere), GT2GS_BUILD_DIR=str(tmp_path / "build"))
    spec = {**transfer_spec(tmp_path, resolution=64, n_views=3, evaluate=False), "preset": "fast"}
    job.start(JobSpec.from_dict(spec))
    messages = []
    while not job.poll().finished:
        messages.append((job.status.stage, job.status.message))
        time.sleep(0.05)
    status = job.status
    assert status.state == DONE, (status, job.stderr_tail())
    assert (
        "compile",
        "compiling the CPU rasterizer with numba (no C++ compiler here; first run only, about a minute)",
    ) in messages
    assert status.report["rasterizer"] == "numba" and status.report["config"]["backend"] == "auto"
    assert not list((tmp_path / "build").glob("raster_cpu-*/*.so")), "a C++ kernel was built"
    assert list((tmp_path / "build" / "numba").glob("warm-*")), "the numba kernel's cache was not written"
    assert colours_differ(read_ply_arrays(status.output).sh_dc, read_ply_arrays(job.path("input.ply")).sh_dc)


def test_cancel_mid_run_stops_the_worker_and_writes_nothing(job, tmp_path):
    """How long the cancel takes is measured by bench/latency.py; a worker that ignored it would be killed
    after the grace period and fail the exit status check below."""
    job.start(JobSpec.from_dict(transfer_spec(tmp_path, stylise_steps=400)))
    wait_for(job, lambda s: s.stage == "stylise" and s.step >= 2)
    status = job.cancel()
    assert status.state == CANCELLED
    assert job.process.returncode == 3  # stopped by itself (SIGTERM handled), not killed
    assert not job.path("out.ply").exists() and not job.path("report.json").exists()


def test_killed_worker_is_a_clear_error(job, tmp_path):
    job.start(JobSpec.from_dict(transfer_spec(tmp_path, stylise_steps=400)))
    wait_for(job, lambda s: s.stage == "stylise")
    os.kill(job.process.pid, signal.SIGKILL)
    status = wait_for(job, lambda s: s.finished, timeout=20)
    assert status.state == ERROR and "killed by signal 9" in status.error
    assert f"how the system stops a process when memory runs out: {MEMORY_ADVICE}" in status.error
    assert not job.path("out.ply").exists()


@needs_prlimit
def test_out_of_memory_is_a_clear_error_and_leaves_no_files(job, tmp_path):
    """A real allocation failure: the worker's address space is capped as soon as it starts, then the
    job asks for 4096 px views on the CPU."""
    cap = address_space_cap()  # measured first: the worker must be capped before it gets far
    job.start(JobSpec.from_dict(transfer_spec(tmp_path, resolution=4096, device="cpu")))
    resource.prlimit(job.process.pid, resource.RLIMIT_AS, (cap, cap))  # past it, allocations fail for real
    status = wait_for(job, lambda s: s.finished, timeout=120)
    assert status.state == ERROR and job.process.returncode == EXIT_MEMORY, (status, job.stderr_tail())
    assert OUT_OF_MEMORY.fullmatch(status.error), status.error
    assert any("can't allocate memory" in line or "MemoryError" in line for line in job.stderr_tail())
    written = {p.relative_to(job.folder).as_posix() for p in job.folder.rglob("*") if p.is_file()}
    assert written == {"job.json", "input.ply", "texture.png"}


def test_bad_input_is_one_readable_line(job, tmp_path):
    job.start(JobSpec.from_dict({**transfer_spec(tmp_path), "texture": "missing.png"}))
    status = wait_for(job, lambda s: s.finished, timeout=60)
    assert status.state == ERROR and job.process.returncode == EXIT_INPUT
    assert "missing.png" in status.error and "Traceback" not in status.error


def test_cameras_that_see_nothing_are_an_input_error_naming_the_files(job, tmp_path):
    save_cameras_json(job.path("cameras.json"), BLIND_CAMERAS["looking-away"])
    job.start(JobSpec.from_dict({**transfer_spec(tmp_path), "views": "cameras.json"}))
    status = wait_for(job, lambda s: s.finished, timeout=60)
    assert status.state == ERROR and job.process.returncode == EXIT_INPUT
    assert status.error.startswith(
        f"{job.path('input.ply')}: no Gaussian is visible in any of the 3 views of "
        f"{job.path('cameras.json')}: all 600 Gaussians are behind the cameras"
    )
    assert not job.path("out.ply").exists() and not job.path("report.json").exists()


def test_messages_use_the_callers_names_for_temporary_exports(job, tmp_path):
    """Blender exports the object and its cameras to the job folder: messages name the object instead."""
    save_cameras_json(job.path("cameras.json"), BLIND_CAMERAS["looking-away"])
    job.start(
        JobSpec.from_dict(
            {
                **transfer_spec(tmp_path),
                "views": "cameras.json",
                "input_name": "object 'Donut'",
                "views_name": "the scene's cameras",
            }
        )
    )
    status = wait_for(job, lambda s: s.finished, timeout=60)
    assert status.state == ERROR and job.process.returncode == EXIT_INPUT
    assert status.error.startswith(
        "object 'Donut': no Gaussian is visible in any of the 3 views of the scene's "
        "cameras: all 600 Gaussians are behind the cameras"
    )
    assert str(job.folder) not in status.error


def test_region_restyles_only_the_masked_gaussians(job, tmp_path):
    selected = np.arange(0, 600, 2)
    np.save(job.path("region.npy"), selected)
    job.start(JobSpec.from_dict({**transfer_spec(tmp_path), "region": "region.npy"}))
    status = wait_for(job, lambda s: s.finished)
    assert status.state == DONE, status.error
    original, result = read_ply_arrays(job.path("input.ply")), read_ply_arrays(status.output)
    kept = np.setdiff1d(np.arange(600), selected)
    assert np.array_equal(result.sh_dc[: len(kept)], original.sh_dc[kept])  # the others, bit-identical, first
    assert colours_differ(result.sh_dc[len(kept) :], original.sh_dc[selected])


def test_region_out_of_range_is_an_input_error(job, tmp_path):
    np.save(job.path("region.npy"), np.array([0, 600]))
    job.start(JobSpec.from_dict({**transfer_spec(tmp_path), "region": "region.npy"}))
    status = wait_for(job, lambda s: s.finished)
    assert status.state == ERROR and job.process.returncode == EXIT_INPUT and "region" in status.error


def test_preview_job_writes_a_png(job, tmp_path):
    job.start(
        JobSpec.from_dict(
            {
                "kind": "preview",
                "input": "input.ply",
                "texture": "texture.png",
                "output": "preview.png",
                "views": 4,
                "preset": "preview",
                "config": {"angle": 30.0},
                "preview_size": 64,
            }
        )
    )
    status = wait_for(job, lambda s: s.finished, timeout=60)
    assert status.state == DONE, status.error
    import cv2

    assert cv2.imread(status.output).shape == (64, 64, 3)


def test_job_spec_rejects_malformed_files(tmp_path):
    path = tmp_path / "job.json"
    for content, message in [
        ("[]", "JSON object"),
        ('{"kind": "x", "input": "a", "texture": "b", "output": "c"}', "unknown job kind"),
        ('{"kind": "preview", "input": "a"}', "lacks texture, output"),
        ('{"kind": "preview", "input": "a", "texture": "b", "output": "c", "views": true}', "views must be"),
    ]:
        path.write_text(content)
        with pytest.raises(Exception, match=message):
            JobSpec.load(path)


def test_worker_command_line_exit_status(tmp_path):
    result = subprocess.run(
        [sys.executable, "-m", "gt2gs_blender.app.worker", str(tmp_path / "none.json")],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=60,
    )
    assert result.returncode == EXIT_INPUT
    (event,) = [json.loads(line) for line in result.stdout.splitlines()]
    assert event["event"] == "error" and "none.json" in event["message"]


def test_pins_match_requirements_txt():
    """Python 3.11's pins are requirements.txt's; 3.13's numpy and OpenCV are requirements-py313.txt's (the
    Blender 5.2 tests' environment: no torch wheel for 3.13 is installed here)."""

    def pinned(name: str) -> dict[str, str]:
        lines = (ROOT / name).read_text().splitlines()
        return dict(line.split("==") for line in lines if "==" in line and not line.startswith("#"))

    py311, py313 = deps.PINS_BY_PYTHON[(3, 11)], deps.PINS_BY_PYTHON[(3, 13)]
    assert {name: pinned("requirements.txt")[name] for name in py311} == py311
    tested = ("numpy", "opencv-contrib-python-headless")
    assert {name: pinned("requirements-py313.txt")[name] for name in tested} == {name: py313[name] for name in tested}
    assert deps.PINS_BY_PYTHON[(3, 13)]["numpy"].startswith("2.")  # numpy 1.26 has no wheel for 3.13
    with pytest.raises(ValueError, match=r"no tested packages for Python 3\.12 \(tested: 3\.11, 3\.13\)"):
        deps.pinned_packages((3, 12))


def test_install_command_targets_the_deps_folder():
    cpu = deps.install_command("/blender/python", "/user/ext/deps", "CPU")
    assert cpu[:3] == ["/blender/python", "-m", "pip"] and "install" in cpu
    assert cpu[cpu.index("--target") + 1] == "/user/ext/deps"
    assert cpu[cpu.index("--extra-index-url") + 1] == deps.TORCH_INDEX["CPU"]
    assert {"torch==2.13.0", "numpy==1.26.4", "opencv-contrib-python-headless==4.11.0.86"} <= set(cpu)
    cuda = deps.install_command("/blender/python", "/user/ext/deps", "CUDA")
    assert cuda[cuda.index("--extra-index-url") + 1].endswith("/cu128")
    with pytest.raises(ValueError):
        deps.install_command("python", "deps", "ROCM")


def test_dependency_status_sees_this_environment(tmp_path):
    status = {d.module: d for d in deps.dependency_status(tmp_path)}
    assert set(status) == {"torch", "numpy", "cv2"}
    assert all(d.ok for d in status.values())
    assert status["numpy"].version == np.__version__


def test_a_local_build_tag_is_the_tested_version():
    assert deps.Dependency("torch", "torch", "2.13.0+cpu", "2.13.0").matches_pin
    assert not deps.Dependency("torch", "torch", "2.12.1", "2.13.0").matches_pin
    assert not deps.Dependency("torch", "torch", None, "2.13.0").matches_pin
