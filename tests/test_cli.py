"""Tests for the command line (app/cli): info, render, demo and the error contract.

Most run ``main([...])`` in-process on small generated scenes, rendering with the portable torch
backend (no compiler needed) except the demo and default-backend tests, which use the automatic
choice (the fast CPU kernel where it builds); two run ``python -m gt2gs_blender`` as a real
subprocess (one of them with its address space capped, to run out of memory for real).
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch

from gt2gs_blender.app.cli import demo, info
from gt2gs_blender.app.cli import main as cli
from gt2gs_blender.app.cli.demo import torus_scene
from gt2gs_blender.core.cameras.cameras_json import load_cameras_json, save_cameras_json
from gt2gs_blender.core.cameras.generate import auto_views
from gt2gs_blender.core.scene.ply import read_ply
from gt2gs_blender.core.scene.ply_write import write_ply

from .worker_tools import OUT_OF_MEMORY, address_space_cap, needs_prlimit

REPO = Path(__file__).resolve().parents[1]
DONUT = REPO.parent / "shared" / "data" / "scenes" / "donut" / "point_cloud.ply"
PORTABLE = ["--backend", "torch", "--device", "cpu"]


@pytest.fixture
def small_ply(tmp_path: Path) -> Path:
    """A 1,200-Gaussian torus written as a 3DGS PLY."""
    path = tmp_path / "torus.ply"
    write_ply(path, torus_scene(n_major=40, n_minor=30))
    return path


def run(capsys: pytest.CaptureFixture, *argv: str) -> tuple[int, str, str]:
    """main(argv) -> (exit code, stdout, stderr)."""
    code = cli.main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def read_png(path: Path) -> np.ndarray:
    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    assert image is not None, path
    return image


def foreground_fraction(path: Path, background_bgr: tuple[int, int, int] = (255, 255, 255)) -> float:
    """Fraction of pixels that differ from the background colour."""
    return float(np.any(read_png(path) != background_bgr, axis=-1).mean())


# -- info -------------------------------------------------------------------------------------------


def test_info_without_a_scene_says_which_rasterizer_runs_and_why(capsys, tmp_path):
    """``info`` alone names the rasterizer ``auto`` resolves to here; with no C++ compiler (CXX and PATH
    pointing nowhere, in a subprocess) it names the numba kernel and why."""
    from gt2gs_blender.core.features.extractor import cpu_has_bfloat16
    from gt2gs_blender.core.render import numba_backend, resolve_backend

    code, out, _ = run(capsys, "info", "--json")
    assert code == 0 and json.loads(out)["rasterizer"] == resolve_backend("auto", "cpu")
    assert json.loads(out)["precision"] == ("bfloat16" if cpu_has_bfloat16() else "float32")
    nowhere = tmp_path / "no-bin"
    nowhere.mkdir()
    env = {**os.environ, "CXX": str(nowhere / "c++"), "PATH": str(nowhere), "GT2GS_BUILD_DIR": str(tmp_path)}
    command = [sys.executable, "-m", "gt2gs_blender", "info"]
    proc = subprocess.run(command, capture_output=True, text=True, env=env, cwd=REPO, timeout=300)
    assert proc.returncode == 0, proc.stderr
    first = proc.stdout.splitlines()[0]
    if numba_backend.installed():
        assert first.startswith("rasterizer:   CPU kernel through numba (no C++ compiler found;"), first
    else:
        assert first.startswith("rasterizer:   portable torch (no C++ compiler found and numba is not installed"), first
    assert "C++ compiler: not found" in proc.stdout
    assert "precision:    VGG in " in proc.stdout


def test_info_generated_ply(capsys, small_ply):
    code, out, err = run(capsys, "info", str(small_ply))
    assert code == 0 and err == ""
    assert "1,200" in out and "binary_little_endian" in out
    assert "float: x y z f_dc_0..2 opacity scale_0..2 rot_0..3" in out


def test_info_json_generated_ply(capsys, small_ply):
    code, out, _ = run(capsys, "info", str(small_ply), "--json")
    info = json.loads(out)
    assert code == 0
    assert (info["count"], info["sh_degree"], info["normals"], info["extras"]) == (1200, 0, False, [])
    assert len(info["properties"]) == 14 and info["properties"][0] == {"name": "x", "type": "float"}
    lo, hi = np.array(info["bounds"]["min"]), np.array(info["bounds"]["max"])
    np.testing.assert_allclose(hi, [1.4, 1.4, 0.4], atol=0.01)
    np.testing.assert_allclose(lo, [-1.4, -1.4, -0.4], atol=0.01)
    assert np.all(np.array(info["robust_bounds"]["min"]) >= lo)
    assert np.all(np.array(info["robust_bounds"]["max"]) <= hi)


def test_info_shared_donut(capsys):
    if not DONUT.is_file():
        pytest.skip(f"shared donut scene not found at {DONUT}")
    code, out, _ = run(capsys, "info", str(DONUT), "--json")
    info = json.loads(out)
    assert code == 0
    assert (info["count"], info["sh_degree"], info["encoding"]) == (45624, 0, "binary_little_endian")


def test_info_as_subprocess(small_ply):
    result = subprocess.run(
        [sys.executable, "-m", "gt2gs_blender", "info", str(small_ply), "--json"],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout)["count"] == 1200


# -- render -----------------------------------------------------------------------------------------


def test_render_generated_views(capsys, small_ply, tmp_path):
    out_dir = tmp_path / "renders"
    code, out, err = run(
        capsys, "render", str(small_ply), "--views", "3", "--width", "64", "--depth", "-o", str(out_dir), *PORTABLE
    )
    assert code == 0, err
    assert str(out_dir) in out and "backend torch" in out
    views = sorted(out_dir.glob("view_*.png"))
    assert [p.name for p in views] == ["view_000.png", "view_001.png", "view_002.png"]
    for view in views:
        assert read_png(view).shape == (64, 64, 3)
        assert 0.05 < foreground_fraction(view) < 0.95
    depth = read_png(out_dir / "depth_000.png")
    assert depth.dtype == np.uint16 and depth.max() == 65535 and (depth == 0).any()
    assert len(load_cameras_json(out_dir / "cameras.json")) == 3


def test_render_cameras_json_at_their_size_and_scaled(capsys, small_ply, tmp_path):
    scene = read_ply(small_ply)
    cameras = auto_views(scene, 2, width=48, height=32) + auto_views(scene, 1, width=40, height=40)
    save_cameras_json(tmp_path / "cameras.json", cameras)
    code, _, err = run(
        capsys,
        "render",
        str(small_ply),
        "--cameras",
        str(tmp_path / "cameras.json"),
        "-o",
        str(tmp_path / "a"),
        "--background",
        "0,0,0",
        *PORTABLE,
    )
    assert code == 0, err
    shapes = [read_png(tmp_path / "a" / f"view_{i:03d}.png").shape for i in range(3)]
    assert shapes == [(32, 48, 3), (32, 48, 3), (40, 40, 3)]
    assert foreground_fraction(tmp_path / "a" / "view_002.png", (0, 0, 0)) > 0.05
    code, _, err = run(
        capsys,
        "render",
        str(small_ply),
        "--cameras",
        str(tmp_path / "a"),
        "--scale",
        "0.5",
        "-o",
        str(tmp_path / "b"),
        *PORTABLE,
    )
    assert code == 0, err
    assert read_png(tmp_path / "b" / "view_000.png").shape == (16, 24, 3)


def test_render_default_backend(capsys, small_ply, tmp_path):
    code, out, err = run(capsys, "render", str(small_ply), "--views", "1", "--width", "32", "-o", str(tmp_path))
    assert code == 0, err
    assert (tmp_path / "view_000.png").is_file() and "backend " in out


# -- errors -----------------------------------------------------------------------------------------


def assert_one_line_error(err: str, *needles: str) -> None:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("gt2gs: error: ") and "Traceback" not in err
    for needle in needles:
        assert needle in lines[0]


def test_missing_file_is_one_line(capsys, tmp_path):
    missing = tmp_path / "nope.ply"
    code, out, err = run(capsys, "info", str(missing))
    assert code == 2 and out == ""
    assert_one_line_error(err, str(missing))
    code, _, err = run(capsys, "render", str(missing), "-o", str(tmp_path / "out"))
    assert code == 2
    assert_one_line_error(err, str(missing))


def test_malformed_ply_is_one_line(capsys, tmp_path):
    bad = tmp_path / "garbage.ply"
    bad.write_bytes(np.random.default_rng(0).integers(0, 256, 500, dtype=np.uint8).tobytes())
    code, out, err = run(capsys, "info", str(bad))
    assert code == 2 and out == ""
    assert_one_line_error(err, str(bad))


def test_bad_cameras_file_is_one_line(capsys, small_ply, tmp_path):
    cams = tmp_path / "cameras.json"
    cams.write_text('[{"width": 10}]')
    code, _, err = run(capsys, "render", str(small_ply), "--cameras", str(cams), "-o", str(tmp_path / "o"))
    assert code == 2
    assert_one_line_error(err, str(cams))


def test_conflicting_options_are_user_errors(capsys, small_ply, tmp_path):
    code, _, err = run(
        capsys, "render", str(small_ply), "--cameras", str(tmp_path), "--width", "10", "-o", str(tmp_path / "o")
    )
    assert code == 2
    assert_one_line_error(err, "--scale")
    code, _, err = run(capsys, "render", str(small_ply), "--background", "2,0,0", "-o", str(tmp_path))
    assert code == 2 and "--background" in err


def test_debug_prints_the_traceback(capsys, tmp_path):
    missing = tmp_path / "nope.ply"
    for argv in (["--debug", "info", str(missing)], ["info", str(missing), "--debug"]):
        code, _, err = run(capsys, *argv)
        assert code == 2
        assert "Traceback (most recent call last)" in err
        assert err.strip().splitlines()[-1].startswith("gt2gs: error: ")


def test_internal_error_exit_code_1(capsys, small_ply, monkeypatch):
    def broken(*args, **kwargs):
        raise RuntimeError("boom")

    monkeypatch.setattr(info, "read_scene", broken)
    code, _, err = run(capsys, "info", str(small_ply))
    assert code == 1
    assert_one_line_error(err, "internal error", "--debug", "boom")


def test_usage_errors_exit_2(capsys):
    assert cli.main([]) == 2
    assert cli.main(["render", "x.ply"]) == 2  # -o is required
    assert cli.main(["--help"]) == 0
    capsys.readouterr()


@pytest.mark.parametrize(
    ("argv", "needles"),
    [
        (["transfer", "a.ply", "t.png", "-o", "o.ply", "--views", "0"], ["transfer:", "--views", "at least 1, got 0"]),
        (["transfer", "a.ply", "t.png", "-o", "o.ply", "--steps", "-1"], ["--steps", "at least 0, got -1"]),
        (["transfer", "a.ply", "t.png", "-o", "o.ply", "--keep-scene", "nan"], ["--keep-scene", "finite"]),
        (["transfer", "a.ply", "t.png", "-o", "o.ply", "--preset", "previe"], ["--preset", "'preview'"]),
        (["transfer", "a.ply", "t.png", "-o", "o.ply", "--up", "-y"], ["--up", "--up=-y"]),
        (["demo", "--views", "0"], ["demo:", "--views", "at least 1"]),
        (["bogus"], ["'bogus'", "'transfer'"]),
    ],
)
def test_a_usage_error_is_one_line_naming_the_flag_the_user_typed(capsys, argv, needles):
    code, out, err = run(capsys, *argv)
    assert code == 2 and out == ""
    assert_one_line_error(err, *needles)
    assert "n_views" not in err and "stylise_steps" not in err and "usage:" not in err


def test_the_reader_closing_the_pipe_is_no_error(small_ply):
    """``info | head``: the output pipe closed before the command writes (its read end shut at once)."""
    process = subprocess.Popen(
        [sys.executable, "-m", "gt2gs_blender", "info", str(small_ply)],
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    process.stdout.close()
    err = process.stderr.read().decode()
    assert process.wait(timeout=120) == cli.EXIT_PIPE
    assert err == ""


# -- demo -------------------------------------------------------------------------------------------


DEMO_FAST = ("--steps", "3", "--resolution", "48", "--views", "3", "--preset", "preview")


def test_demo_on_a_given_scene(capsys, small_ply, tmp_path):
    out_dir = tmp_path / "demo"
    code, out, err = run(capsys, "demo", "--scene", str(small_ply), "--out", str(out_dir), *DEMO_FAST)
    assert code == 0, err
    stylised = read_ply(out_dir / "stylised.ply")
    original = read_ply(small_ply)
    report = json.loads((out_dir / "report.json").read_text())
    assert report["n_gaussians"] == len(stylised) and report["n_views"] == 3
    assert all(torch.isfinite(t).all() for t in stylised.tensors().values())
    assert float(stylised.sh_dc.mean(0).sub(original.sh_dc.mean(0)).abs().max()) > 1e-3  # colours changed
    strip = read_png(out_dir / "before_after.png")
    assert strip.shape == (2 * 256, 5 * 256, 3)
    assert str(out_dir / "before_after.png") in out


def test_demo_generates_a_torus_without_shared(capsys, tmp_path, monkeypatch):
    monkeypatch.setattr(demo, "SHARED_DONUT", tmp_path / "absent.ply")
    monkeypatch.setattr(demo, "DEMO_TEXTURE", tmp_path / "absent.jpg")
    code, out, err = run(capsys, "demo", "--out", str(tmp_path / "d"), *DEMO_FAST)
    assert code == 0, err
    assert "generated torus" in out and "generated stripes" in out
    assert (tmp_path / "d" / "stylised.ply").is_file()


def test_transfer_command_writes_scene_report_and_strip(capsys, small_ply, tmp_path, shared):
    out = tmp_path / "out.ply"
    texture = shared / "data" / "textures" / "brick_wall.jpg"
    code, _stdout, err = run(
        capsys,
        "transfer",
        str(small_ply),
        str(texture),
        "-o",
        str(out),
        *DEMO_FAST,
        "--report",
        str(tmp_path / "r.json"),
        "--strip",
        str(tmp_path / "s.png"),
    )
    assert code == 0, err
    report = json.loads((tmp_path / "r.json").read_text())
    assert len(read_ply(out)) == report["n_gaussians"] >= 1200  # the layout's detail split adds splats
    assert report["weights"]["fallback"] is False  # the shared VGG-19 weights were found
    assert read_png(tmp_path / "s.png").shape == (512, 1280, 3)


def test_transfer_command_bad_texture_is_one_line(capsys, small_ply, tmp_path):
    bad = tmp_path / "texture.png"
    bad.write_bytes(b"not an image")
    code, _, err = run(capsys, "transfer", str(small_ply), str(bad), "-o", str(tmp_path / "o.ply"), *DEMO_FAST)
    assert code == 2
    assert_one_line_error(err, str(bad))
    assert not (tmp_path / "o.ply").exists()


@needs_prlimit
def test_transfer_out_of_memory_is_one_line_and_writes_nothing(small_ply, tmp_path):
    """A real allocation failure: the command runs with its address space capped (RLIMIT_AS) and asks
    for 4096 px views; it used to end as an 'internal error' quoting torch's allocator."""
    cap = address_space_cap()
    out = tmp_path / "out" / "styled.ply"
    out.parent.mkdir()
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "gt2gs_blender",
            "transfer",
            str(small_ply),
            str(stripe_png(tmp_path)),
            "-o",
            str(out),
            "--report",
            str(out.parent / "r.json"),
            *PORTABLE,
            "--preset",
            "preview",
            "--views",
            "3",
            "--steps",
            "2",
            "--resolution",
            "4096",
        ],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=300,
        preexec_fn=lambda: resource.setrlimit(resource.RLIMIT_AS, (cap, cap)),
    )
    assert result.returncode == 2, result.stderr
    errors = [line for line in result.stderr.splitlines() if line.startswith("gt2gs: error: ")]
    assert len(errors) == 1 and "Traceback" not in result.stderr
    assert OUT_OF_MEMORY.fullmatch(errors[0].removeprefix("gt2gs: error: ")), errors[0]
    assert list(out.parent.iterdir()) == []


def stripe_png(folder: Path) -> Path:
    """A generated 128 px diagonal stripe texture written as PNG."""
    y, x = np.mgrid[0:128, 0:128]
    image = ((((x + y) // 8) % 2) * 200 + 30).astype(np.uint8)
    path = folder / "stripes.png"
    cv2.imwrite(str(path), np.stack([image, image // 2, 255 - image], axis=-1))
    return path


def test_transfer_command_region_and_switches(capsys, small_ply, tmp_path):
    """--region keeps the other Gaussians bit-identical (they come first); the switches reach the report."""
    region = tmp_path / "region.npy"
    np.save(region, np.arange(0, 1200, 4))
    out = tmp_path / "out.ply"
    code, _, err = run(
        capsys,
        "transfer",
        str(small_ply),
        str(stripe_png(tmp_path)),
        "-o",
        str(out),
        *DEMO_FAST,
        "--region",
        str(region),
        "--angle",
        "30",
        "--no-gt2",
        "--no-afcm",
        "--no-gpb",
        "--stylise-geometry",
        "on",
        "--no-densify",
        "--no-skip-hidden",
        "--no-mixed-precision",
        "--threads",
        "1",
        "--texture-height",
        "96",
        "--depth-ratio",
        "1.5",
        "--object-backdrop",
        "--report",
        str(tmp_path / "r.json"),
    )
    assert code == 0, err
    before, after = read_ply(small_ply), read_ply(out)
    outside = np.setdiff1d(np.arange(1200), np.arange(0, 1200, 4))
    assert torch.equal(after.means[: len(outside)], before.means[outside])
    assert torch.equal(after.sh_dc[: len(outside)], before.sh_dc[outside])
    config = json.loads((tmp_path / "r.json").read_text())["config"]
    assert config["angle"] == 30 and not any(
        config[k] for k in ("gt2", "afcm", "gpb", "densify", "skip_hidden", "mixed_precision")
    )
    assert config["threads"] == 1 and config["texture_height"] == 96
    assert config["stylise_geometry"] == "on" and config["object_backdrop"]
    assert config["depth_ratio"] == 1.5


@pytest.mark.parametrize(
    ("values", "words"),
    [
        (np.zeros((3, 3), dtype=np.float32), "1-D array of indices or booleans"),
        (np.ones(5, dtype=bool), "mask has (5,) entries for a scene of 1200 Gaussians"),
        (np.zeros(1200, dtype=bool), "selects no Gaussian"),
        (np.array([], dtype=np.int64), "selects no Gaussian"),
        (np.array([5, 10_000_000]), "indices must lie in 0..1199 (the scene's 1200 Gaussians), got 5..10000000"),
    ],
    ids=["floats", "short-mask", "all-false", "no-index", "out-of-range"],
)
def test_transfer_command_bad_region_is_one_line_naming_the_file(capsys, small_ply, tmp_path, values, words):
    region = tmp_path / "region.npy"
    np.save(region, values)
    code, _, err = run(
        capsys,
        "transfer",
        str(small_ply),
        str(stripe_png(tmp_path)),
        "-o",
        str(tmp_path / "o.ply"),
        *DEMO_FAST,
        "--region",
        str(region),
    )
    assert code == 2
    assert_one_line_error(err, f"{region}: ", words)


def test_a_foreign_file_given_as_a_region_weights_or_capture_is_named_for_what_it_is_not(capsys, small_ply, tmp_path):
    """numpy reads any non-.npy file as a pickle and says so, torch's errors for a text file say nothing about it, and
    a missing capture folder was "no image folder": each is now one line saying what the file is not."""
    text = tmp_path / "notes.txt"
    text.write_text("hello")
    transfer = ["transfer", str(small_ply), str(stripe_png(tmp_path)), "-o", str(tmp_path / "o.ply"), *DEMO_FAST]
    code, _, err = run(capsys, *transfer, "--region", str(text))
    assert code == 2
    assert_one_line_error(err, f"{text}: ", "the region is not a .npy file (it starts with b'hello')")
    code, _, err = run(capsys, *transfer, "--weights", str(text))  # found when the run loads its network
    assert code == 2
    assert_one_line_error(err.strip().splitlines()[-1], f"{text}: ", "is not a PyTorch weights file (.pth)")
    code, _, err = run(capsys, "fit", str(tmp_path / "absent"), "--out", str(tmp_path / "fit"))
    assert code == 2
    assert_one_line_error(err, f"{tmp_path / 'absent'}: ", "no such folder")


@pytest.mark.parametrize(
    "argv",
    [
        ["convert", "in.ply", ""],
        ["transfer", "s.ply", "t.png", "-o", ""],
        ["render", "", "--out", "views"],
        ["info", ""],
        ["transfer", "s.ply", "t.png", "-o", "o.ply", "--report", ""],
    ],
)
def test_an_empty_file_name_is_one_line_not_the_current_folder(capsys, argv):
    """argparse would turn '' into Path('.'), the current folder: refused first, saying which argument."""
    assert cli.main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err == f"gt2gs: error: '' (argument {argv.index('') + 1}): an empty file name or value; give one"


def test_the_before_after_strip_shows_the_run_s_own_cameras_when_given():
    """A capture's strip is four of its own views, spread over them, at the strip's size; else a ring about up."""
    from gt2gs_blender.app.jobs import STRIP_SIZE, strip_cameras
    from gt2gs_blender.core.cameras.generate import auto_views

    from .test_transfer import blob_scene

    scene = blob_scene(300)
    given = auto_views(scene, 10, width=400, height=300)
    picked = strip_cameras(scene, given, "+z")
    assert [c.name for c in picked] == [given[i].name for i in (0, 2, 5, 7)]
    assert all(max(c.width, c.height) == STRIP_SIZE for c in picked)
    ring = strip_cameras(scene, None, "-y")
    assert all(float(-c.world_to_cam[1, :3] @ np.array([0.0, -1.0, 0.0])) > 0.8 for c in ring)


def test_the_strip_lines_up_views_of_any_shape_each_centred_in_its_square_cell(tmp_path):
    """Given 4:3 cameras, each view is rendered whole, centred between white bands in a STRIP_SIZE square (the
    rows of the strip keep one height, so the swatch and the batch sheet's cells line up); the automatic ring is cut
    to a wide torus and enlarged, so the torus covers more of its cells than of the square ring's views."""
    from gt2gs_blender.app.jobs import STRIP_SIZE, strip_cameras, write_before_after
    from gt2gs_blender.core.render import render

    scene = torus_scene(n_major=24, n_minor=12)
    given = auto_views(scene, 8, width=400, height=300)
    texture = np.full((32, 32, 3), 0.5, np.float32)
    write_before_after(tmp_path / "strip.png", scene, scene, texture, given)
    strip = read_png(tmp_path / "strip.png")[..., ::-1]
    assert strip.shape == (2 * STRIP_SIZE, 5 * STRIP_SIZE, 3)
    (first, *_) = strip_cameras(scene, given, "+z")
    band = (STRIP_SIZE - first.height) // 2
    assert (first.width, band) == (STRIP_SIZE, 32)
    cell = strip[:STRIP_SIZE, STRIP_SIZE : 2 * STRIP_SIZE]
    assert (cell[:band] == 255).all() and (cell[band + first.height :] == 255).all()
    direct = render(scene, [first], background=(1.0, 1.0, 1.0)).colors[0].clamp(0, 1).numpy()
    assert np.abs(cell[band : band + first.height].astype(int) - (direct * 255 + 0.5).astype(int)).max() <= 1
    ring = strip_cameras(scene, None, "+z")
    square = auto_views(scene, 4, width=STRIP_SIZE, height=STRIP_SIZE, elevation_deg=30.0)
    assert all(max(c.width, c.height) == STRIP_SIZE and c.width > c.height for c in ring)
    covered = [float((render(scene, cams, render_depth=False).alphas > 0.5).float().mean()) for cams in (ring, square)]
    assert covered[0] * ring[0].width * ring[0].height / STRIP_SIZE**2 > 1.2 * covered[1]


# -- preview ----------------------------------------------------------------------------------------


def test_preview_command_writes_the_runs_first_view_as_the_engine_draws_it(capsys, small_ply, tmp_path):
    """The picture is the engine's own preview of the run the same options would start (the oracle: the API's
    ``preview`` with the same settings), the texture visibly on the scene, turned by ``--angle``."""
    from gt2gs_blender.core.transfer.orientation_preview import preview
    from gt2gs_blender.core.transfer.presets import preset
    from gt2gs_blender.core.transfer.texture import load_texture

    x = np.arange(128)[None, :].repeat(128, axis=0)
    bands = np.where((x // 32) % 2, 230, 20).astype(np.uint8)  # bands broader than the small torus's splats
    texture = tmp_path / "bands.png"
    cv2.imwrite(str(texture), np.stack([bands, bands, bands], axis=-1))
    pictures = {}
    texture_only = ("--keep-scene", "0", "--scene-colour", "0")  # the torus's own checker would hide the turn
    for angle in ("0", "45"):
        out = tmp_path / f"preview{angle}.png"
        argv = ["preview", str(small_ply), str(texture), "-o", str(out), "--preset", "preview", *PORTABLE]
        code, stdout, err = run(capsys, *argv, *texture_only, "--views", "4", "--angle", angle, "--size", "96")
        assert code == 0, err
        assert str(out) in stdout and "splats" in stdout
        pictures[angle] = read_png(out)[..., ::-1]
    config = preset("preview", n_views=4, backend="torch", device="cpu", keep_scene=0.0, scene_colour=0.0)
    expected = preview(read_ply(small_ply), load_texture(texture), None, config, size=96).image
    np.testing.assert_array_equal(pictures["0"], expected)
    assert pictures["0"].shape == (60, 96, 3)  # the run's first view, cut to the wide torus, 96 px across
    on = (pictures["0"] < 250).any(axis=-1)
    assert on.mean() > 0.05  # the torus is in view
    assert np.abs(pictures["0"].astype(int) - pictures["45"].astype(int))[on].mean() > 10  # the angle turns it


def test_preview_to_a_name_that_is_no_png_is_refused(capsys, small_ply, tmp_path):
    out = tmp_path / "preview.jpg"
    code, _, err = run(capsys, "preview", str(small_ply), str(stripe_png(tmp_path)), "-o", str(out))
    assert code == 2 and not out.exists()
    assert_one_line_error(err, str(out), ".png")
