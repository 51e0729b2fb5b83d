"""Bad paths (issue 36, "never lose the user's file"): an output that names an input (the same path, through
``./``, a symlink or a hard link, or a file inside an input folder) or another output, an output that cannot
be written (missing folder, a file as its folder, a folder that takes no files, an existing folder, a name too
long), and inputs that are no file (named pipes, sockets, devices, folders). Every command refuses them before
any work: exit code 2, one line on stderr naming the user's path (never a temp file), the inputs' bytes
unchanged and nothing left behind. A run's outputs are written all or nothing.

The tests run as root, where permission bits do not stop a write: "cannot write" is a file used as a folder
(ENOTDIR) or a folder under /proc, which takes no new files whoever asks.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import cv2
import numpy as np
import pytest

from gt2gs_blender.app.cli import main as cli
from gt2gs_blender.app.cli import render as render_cmd
from gt2gs_blender.app.cli import transfer as transfer_cmd
from gt2gs_blender.app.cli.demo import torus_scene
from gt2gs_blender.core import atomic
from gt2gs_blender.core.cameras.cameras_json import save_cameras_json
from gt2gs_blender.core.cameras.generate import auto_views
from gt2gs_blender.core.errors import InputFileError
from gt2gs_blender.core.scene.files import write_splats

QUICK = ("--steps", "2", "--resolution", "32", "--preset", "preview", "--backend", "torch", "--device", "cpu")
FAST = (*QUICK, "--views", "2")
LONG_NAME = "x" * 300 + ".ply"
SCENES = {"ply": "scene.ply", "spz": "scene.spz", "splat": "scene.splat", "compressed-ply": "scene.compressed.ply"}
ALIASES = ("same", "dot", "symlink", "hardlink")


class Hung(BaseException):
    """Raised by the alarm when a command blocks (a pipe opened for reading waits for a writer)."""


@pytest.fixture
def world(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A folder of small inputs, the working directory of the test: scenes in every writable format, a texture,
    cameras, a region, an LLFF-like folder and an unpacked-SOG-like folder."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("HOME", str(tmp_path / "home"))  # a bank cache written by a run would go here
    scene = torus_scene(n_major=20, n_minor=10)
    for name in SCENES.values():
        write_splats(name, scene)
    y, x = np.mgrid[0:64, 0:64]
    cv2.imwrite("texture.png", np.dstack([(x + y) % 32 * 8, x * 2, y * 2]).astype(np.uint8))
    save_cameras_json("cameras.json", auto_views(scene, 2, width=32, height=32))
    np.save("region.npy", np.arange(10))
    os.mkdir("llff")
    np.save("llff/poses_bounds.npy", np.zeros((3, 17)))
    os.mkdir("llff/images_8")
    os.mkdir("folder")
    os.mkdir("sog")
    Path("sog/meta.json").write_text("{}")
    write_splats("sog/extra.ply", scene)
    Path("afile").write_bytes(b"a file, not a folder")
    return tmp_path


def snapshot(root: Path) -> dict[str, str]:
    """Every entry under ``root`` (not following links): a file's sha256, a link's target, or 'folder'."""
    entries = {}
    for folder, dirs, files in os.walk(root):
        for name in dirs + files:
            path = Path(folder, name)
            key = str(path.relative_to(root))
            if path.is_symlink():
                entries[key] = "-> " + os.readlink(path)
            elif path.is_dir():
                entries[key] = "folder"
            elif path.is_file():
                entries[key] = hashlib.sha256(path.read_bytes()).hexdigest()
            else:
                entries[key] = "special"
    return entries


def alias(path: str, kind: str) -> str:
    """Another name for the existing file ``path``: itself, through ``./``, a symlink or a hard link."""
    if kind == "same":
        return path
    if kind == "dot":
        return os.path.join(os.path.dirname(path), ".", os.path.basename(path))
    name = f"{kind}-{os.path.basename(path)}"
    (os.symlink if kind == "symlink" else os.link)(os.path.basename(path) if kind == "symlink" else path, name)
    return name


@contextlib.contextmanager
def no_hang(seconds: int = 60) -> Iterator[None]:
    """Fail with Hung instead of blocking for ever."""

    def fire(*_: object) -> None:
        raise Hung(f"blocked for {seconds} s")

    previous = signal.signal(signal.SIGALRM, fire)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


def refused(capsys: pytest.CaptureFixture, root: Path, argv: list[str], named: str) -> str:
    """Run the CLI on ``argv``; assert exit 2, one stderr line naming ``named`` (no temp file), no output on
    stdout (no work started) and every file under ``root`` as it was. The error line. With ``capfd`` for
    ``capsys``, what C libraries print on descriptor 2 counts too."""
    capsys.readouterr()
    before = snapshot(root)
    with no_hang():
        code = cli.main(argv)
    out, err = capsys.readouterr()
    lines = err.splitlines()
    assert code == 2, err
    assert len(lines) == 1 and lines[0].startswith("gt2gs: error: "), err
    assert str(Path(named)) in lines[0] and ".tmp" not in lines[0], lines[0]
    assert out == ""
    assert snapshot(root) == before
    return lines[0]


def transfer_argv(
    output: str = "out.ply", scene: str = "scene.ply", texture: str = "texture.png", *extra: str
) -> list[str]:
    return ["transfer", scene, texture, "-o", output, *extra, *(QUICK if "--cameras" in extra else FAST)]


# -- 1. an output that names an input --------------------------------------------------------------------


@pytest.mark.parametrize("kind", ALIASES)
@pytest.mark.parametrize("fmt", sorted(SCENES))
def test_convert_onto_its_input_is_refused(capsys, world, fmt, kind):
    output = alias(SCENES[fmt], kind)
    line = refused(capsys, world, ["convert", SCENES[fmt], output], output)
    assert "would overwrite the scene" in line


TRANSFER_INPUTS = {
    "scene": ("scene.ply", ()),
    "texture": ("texture.png", ()),
    "cameras": ("cameras.json", ("--cameras", "cameras.json")),
    "region": ("region.npy", ("--region", "region.npy")),
}
TRANSFER_OUTPUTS = {"-o": (), "--report": ("--report",), "--strip": ("--strip",)}


@pytest.mark.parametrize("kind", ALIASES)
@pytest.mark.parametrize("flag", sorted(TRANSFER_OUTPUTS))
@pytest.mark.parametrize("source", sorted(TRANSFER_INPUTS))
def test_transfer_onto_any_of_its_inputs_is_refused(capsys, world, source, flag, kind):
    path, given = TRANSFER_INPUTS[source]
    target = alias(path, kind)
    if flag == "-o":
        argv = transfer_argv(target, "scene.ply", "texture.png", *given)
    else:
        argv = transfer_argv("out.ply", "scene.ply", "texture.png", *given, flag, target)
    line = refused(capsys, world, argv, target)
    assert f"would overwrite the {source}" in line


@pytest.mark.parametrize("kind", ["same", "dot", "symlink"])
@pytest.mark.parametrize("pair", [("-o", "--report"), ("-o", "--strip"), ("--report", "--strip")])
def test_transfer_outputs_naming_one_file_are_refused(capsys, world, pair, kind):
    Path("first.out").write_bytes(b"an old output")
    second = alias("first.out", kind)
    flags = dict(zip(pair, ("first.out", second)))
    argv = transfer_argv(flags.get("-o", "out.ply"), "scene.ply", "texture.png")
    argv += [arg for flag in ("--report", "--strip") if flag in flags for arg in (flag, flags[flag])]
    assert "name the same file" in refused(capsys, world, argv, "first.out" if pair[0] != "-o" else second)


@pytest.mark.parametrize(
    "argv, named",
    [
        (["convert", "sog", "sog/extra.ply"], "sog/extra.ply"),
        (["convert", "sog/meta.json", "sog/extra.ply"], "sog/extra.ply"),
        (["convert", "./sog/", "./sog/extra.ply"], "sog/extra.ply"),
        (transfer_argv("sog/extra.ply", "sog"), "sog/extra.ply"),
        (transfer_argv("out.ply", "sog/meta.json", "texture.png", "--report", "sog/extra.ply"), "sog/extra.ply"),
    ],
    ids=["convert-folder", "convert-meta", "convert-dot", "transfer-o", "transfer-report"],
)
def test_an_output_over_a_file_of_an_input_folder_is_refused(capsys, world, argv, named):
    assert "would overwrite the scene" in refused(capsys, world, argv, named)


@pytest.mark.parametrize("kind", ["same", "dot", "symlink"])
def test_render_over_its_cameras_file_is_refused(capsys, world, kind):
    os.mkdir("views")
    save_cameras_json("views/cameras.json", auto_views(torus_scene(n_major=20, n_minor=10), 2, width=32, height=32))
    out = {"same": "views", "dot": "./views", "symlink": None}[kind]
    if out is None:
        os.symlink("views", "linked-views")
        out = "linked-views"
    line = refused(capsys, world, ["render", "scene.ply", "-o", out, "--cameras", "views/cameras.json"], out)
    assert "would overwrite the cameras" in line


def test_render_into_its_cameras_folder_is_refused(capsys, world):
    os.mkdir("views")
    save_cameras_json("views/cameras.json", auto_views(torus_scene(n_major=20, n_minor=10), 2, width=32, height=32))
    assert "would overwrite the cameras" in refused(
        capsys, world, ["render", "scene.ply", "-o", "views", "--cameras", "views"], "views/cameras.json"
    )


@pytest.mark.parametrize(
    "argv, named, words",
    [
        (["fit", "llff", "--out", "fitted", "--report", "llff/poses_bounds.npy"], "llff/poses_bounds.npy", "LLFF"),
        (["fit", "llff", "--out", "fitted", "--report", "./llff/poses_bounds.npy"], "llff/poses_bounds.npy", "LLFF"),
        (["fit", "llff", "--out", "fitted", "--report", "fitted/cameras.json"], "fitted/cameras.json", "same file"),
        (["fit", "llff", "--out", "llff", "--report", "llff/cameras.json"], "llff/cameras.json", "LLFF"),
    ],
    ids=["report-on-poses", "report-on-poses-dot", "report-on-output", "out-over-input-file"],
)
def test_fit_outputs_over_its_input_or_each_other_are_refused(capsys, world, argv, named, words):
    if argv[3] == "llff":
        Path("llff/cameras.json").write_text("[]")  # a file of the input folder the run would overwrite
    assert words in refused(capsys, world, argv, named)


@pytest.mark.parametrize("which", ["scene", "texture"])
def test_demo_over_its_inputs_is_refused(capsys, world, which):
    os.mkdir("demo")
    inputs = {"scene": "scene.ply", "texture": "texture.png"}
    inputs[which] = {"scene": "demo/stylised.ply", "texture": "demo/before_after.png"}[which]
    os.replace(f"{which}{Path(inputs[which]).suffix}", inputs[which])
    argv = ["demo", "--out", "demo", "--scene", inputs["scene"], "--texture", inputs["texture"], *FAST]
    assert f"would overwrite the {which}" in refused(capsys, world, argv, inputs[which])


# -- 3 and 7. outputs that cannot be written, found before any work -----------------------------------------

FILE_OUTPUTS: dict[str, Callable[[str], list[str]]] = {
    "convert": lambda out: ["convert", "scene.ply", out],
    "transfer -o": lambda out: transfer_argv(out),
    "transfer --report": lambda out: transfer_argv("out.ply", "scene.ply", "texture.png", "--report", out),
    "transfer --strip": lambda out: transfer_argv("out.ply", "scene.ply", "texture.png", "--strip", out),
    "fit --report": lambda out: ["fit", "llff", "--out", "fitted", "--report", out],
}
FILE_PLACES = {
    "missing-folder": ("no/such/folder/out.ply", "does not exist"),
    "file-as-folder": ("afile/out.ply", "afile is not a folder"),
    "proc": ("/proc/gt2gs-out.ply", "takes no new files"),
    "existing-folder": ("folder", "it is a folder"),
    "long-name": (LONG_NAME, "too long"),
    "named-pipe": ("pipe.ply", "named pipe"),
}


@pytest.mark.parametrize("place", sorted(FILE_PLACES))
@pytest.mark.parametrize("command", sorted(FILE_OUTPUTS))
def test_an_output_that_cannot_be_written_is_refused_before_any_work(capsys, world, command, place):
    out, words = FILE_PLACES[place]
    if place == "named-pipe":
        os.mkfifo(out)
    line = refused(capsys, world, FILE_OUTPUTS[command](out), out)
    assert words in line


FOLDER_OUTPUTS: dict[str, Callable[[str], list[str]]] = {
    "render": lambda out: ["render", "scene.ply", "-o", out, "--views", "2", "--width", "16", "--backend", "torch"],
    "fit": lambda out: ["fit", "llff", "--out", out, "--iterations", "1"],
    "demo": lambda out: ["demo", "--scene", "scene.ply", "--texture", "texture.png", "--out", out, *FAST],
}
FOLDER_PLACES = {
    "file-as-folder": ("afile/views", "afile is not a folder"),
    "is-a-file": ("afile", "afile is not a folder"),
    "proc": ("/proc/gt2gs-views", "takes no new files"),
    "long-name": ("x" * 300, "too long"),
}


@pytest.mark.parametrize("place", sorted(FOLDER_PLACES))
@pytest.mark.parametrize("command", sorted(FOLDER_OUTPUTS))
def test_an_output_folder_that_cannot_be_written_is_refused_before_any_work(capsys, world, command, place):
    out, words = FOLDER_PLACES[place]
    assert words in refused(capsys, world, FOLDER_OUTPUTS[command](out), out)


# -- 4. inputs that are no file: refused before they are opened ---------------------------------------------


def make_input(kind: str) -> str:
    """A path to something that is no regular file: a named pipe, a socket, a device or a folder."""
    if kind == "pipe":
        os.mkfifo("pipe")
        return "pipe"
    if kind == "socket":
        server = socket.socket(socket.AF_UNIX)
        server.bind("sock")
        return "sock"
    return {"device": "/dev/zero", "folder": "folder"}[kind]


NOT_FILES = {
    ("info", "pipe"): lambda p: ["info", p],
    ("info", "socket"): lambda p: ["info", p],
    ("info", "device"): lambda p: ["info", p],
    ("convert", "pipe"): lambda p: ["convert", p, "out.ply"],
    ("convert", "device"): lambda p: ["convert", p, "out.ply"],
    ("render scene", "pipe"): lambda p: ["render", p, "-o", "views", "--views", "2", "--width", "16"],
    ("render cameras", "pipe"): lambda p: ["render", "scene.ply", "-o", "views", "--cameras", p],
    ("transfer scene", "pipe"): lambda p: transfer_argv("out.ply", p),
    ("transfer scene", "device"): lambda p: transfer_argv("out.ply", p),
    ("transfer texture", "pipe"): lambda p: transfer_argv("out.ply", "scene.ply", p),
    ("transfer texture", "socket"): lambda p: transfer_argv("out.ply", "scene.ply", p),
    ("transfer texture", "device"): lambda p: transfer_argv("out.ply", "scene.ply", p),
    ("transfer texture", "folder"): lambda p: transfer_argv("out.ply", "scene.ply", p),
    ("transfer region", "pipe"): lambda p: transfer_argv("out.ply", "scene.ply", "texture.png", "--region", p),
    ("transfer region", "folder"): lambda p: transfer_argv("out.ply", "scene.ply", "texture.png", "--region", p),
    ("transfer cameras", "pipe"): lambda p: transfer_argv("out.ply", "scene.ply", "texture.png", "--cameras", p),
    ("demo scene", "pipe"): lambda p: ["demo", "--scene", p, "--texture", "texture.png", "--out", "d", *FAST],
    ("demo texture", "pipe"): lambda p: ["demo", "--scene", "scene.ply", "--texture", p, "--out", "d", *FAST],
    ("fit", "pipe"): lambda p: ["fit", p, "--out", "fitted"],
}


@pytest.mark.parametrize("case", sorted(NOT_FILES), ids=lambda case: "-".join(case).replace(" ", "-"))
def test_an_input_that_is_no_file_is_refused_without_blocking(capsys, world, case):
    path = make_input(case[1])
    words = {"pipe": "named pipe", "socket": "socket", "device": "device", "folder": "is a folder"}[case[1]]
    assert words in refused(capsys, world, NOT_FILES[case](path), path)


# -- 8. one line, without the codecs' own lines ------------------------------------------------------------


@pytest.mark.parametrize("cut", [0.02, 0.3, 0.7, 0.99])
@pytest.mark.parametrize("command", ["transfer", "demo"])
def test_a_damaged_texture_is_one_line_without_the_codecs_lines(capfd, world, command, cut):
    noise = np.random.default_rng(0).integers(0, 256, (64, 64, 3), dtype=np.uint8)
    data = cv2.imencode(".png", noise)[1].tobytes()
    Path("damaged.png").write_bytes(data[: int(len(data) * cut)])
    argv = {
        "transfer": transfer_argv("out.ply", "scene.ply", "damaged.png"),
        "demo": ["demo", "--scene", "scene.ply", "--texture", "damaged.png", "--out", "d", *FAST],
    }[command]
    refused(capfd, world, argv, "damaged.png")


# -- all or nothing --------------------------------------------------------------------------------------


def test_transfer_to_a_format_it_cannot_write_is_refused_before_any_work(capsys, world):
    assert "read only" in refused(capsys, world, transfer_argv("out.sog"), "out.sog")


@pytest.mark.parametrize(
    ("argv", "named", "words"),
    [
        (transfer_argv("out.txt"), "out.txt", "not a splat file name"),
        (transfer_argv("out"), "out", ".ply, .compressed.ply, .spz, .splat"),
        (["convert", "scene.ply", "out.webp"], "out.webp", "not a splat file name"),
        (transfer_argv("out.ply", "scene.ply", "texture.png", "--strip", "strip.jpg"), "strip.jpg", ".png"),
        (transfer_argv("out.ply", "scene.ply", "texture.png", "--report", "report.png"), "report.png", ".json"),
    ],
)
def test_an_output_whose_name_hides_what_it_holds_is_refused_before_any_work(capsys, world, argv, named, words):
    assert words in refused(capsys, world, argv, named)


def test_convert_with_a_format_given_writes_any_name(capsys, world):
    assert cli.main(["convert", "scene.ply", "scene.bin", "--format", "spz"]) == 0
    assert Path("scene.bin").read_bytes()[:2] == b"\x1f\x8b"  # SPZ: a gzip stream
    assert cli.main(["info", "scene.bin"]) == 0  # read back by its content


def test_a_splat_file_must_be_named_so_to_be_read_back(capsys, world):
    """A .splat has no signature: readers know it by its name, so another name is refused before any work."""
    assert ".splat" in refused(capsys, world, ["convert", "scene.ply", "scene.bin", "--format", "splat"], "scene.bin")


def test_a_read_only_output_is_refused_and_kept(capsys, world):
    """Permission bits that say "read-only" are honoured even by root, whose writes they would not stop."""
    write_splats("old.ply", torus_scene(n_major=8, n_minor=4))
    os.chmod("old.ply", 0o444)
    assert "read-only" in refused(capsys, world, ["convert", "scene.spz", "old.ply"], "old.ply")


def test_an_output_written_over_a_file_keeps_its_permissions(capsys, world):
    write_splats("private.ply", torus_scene(n_major=8, n_minor=4))
    os.chmod("private.ply", 0o600)
    assert cli.main(["convert", "scene.spz", "private.ply"]) == 0
    assert os.stat("private.ply").st_mode & 0o777 == 0o600
    assert cli.main(["convert", "scene.spz", "fresh.ply"]) == 0  # a new file: the umask's permissions
    assert os.stat("fresh.ply").st_mode & 0o777 == 0o666 & ~_umask()


def _umask() -> int:
    """This process's umask (read by setting it and back)."""
    mask = os.umask(0)
    os.umask(mask)
    return mask


def test_transfer_whose_last_output_fails_leaves_none(capsys, world, monkeypatch):
    def no_strip(*_: object) -> None:
        raise OSError(28, "No space left on device", "strip.png")

    monkeypatch.setattr(transfer_cmd, "write_before_after", no_strip)
    before = snapshot(world)
    code = cli.main(transfer_argv("out.ply", "scene.ply", "texture.png", "--report", "r.json", "--strip", "strip.png"))
    err = capsys.readouterr().err
    assert code == 2 and "strip.png: No space left on device" in err.splitlines()[-1]
    assert {k: v for k, v in snapshot(world).items() if not k.startswith("home")} == before


def test_transfer_writes_every_output_when_it_succeeds(capsys, world):
    code = cli.main(transfer_argv("out.ply", "scene.ply", "texture.png", "--report", "r.json", "--strip", "s.png"))
    out, err = capsys.readouterr()
    assert code == 0, err
    assert all(Path(name).is_file() for name in ("out.ply", "r.json", "s.png"))
    assert "stylised scene: out.ply" in out and not list(world.glob(".*.tmp"))


def test_render_failing_midway_leaves_no_view_and_no_folder(capsys, world, monkeypatch):
    real = render_cmd.write_png
    written = []

    def fail_third(path: Path, pixels: np.ndarray) -> None:
        written.append(path)
        if len(written) == 3:
            raise OSError(5, "Input/output error", str(path))
        real(path, pixels)

    monkeypatch.setattr(render_cmd, "write_png", fail_third)
    before = snapshot(world)
    argv = ["render", "scene.ply", "-o", "new/views", "--views", "4", "--width", "16", "--backend", "torch"]
    assert cli.main(argv) == 2
    assert "view_002.png: Input/output error" in capsys.readouterr().err
    assert snapshot(world) == before  # the two views written are gone, and the folders made for them


@pytest.mark.parametrize("signum", cli.STOP_SIGNALS, ids=lambda signum: signal.Signals(signum).name)
def test_a_command_stopped_by_a_signal_leaves_nothing_half_written(tmp_path, signum):
    """SIGTERM or SIGHUP (``kill``, a closed terminal) while a render writes its views: the command unwinds as
    Ctrl-C does, so the views written so far and the folder made for them are removed, and it exits 128 + N."""
    write_splats(tmp_path / "scene.ply", torus_scene(n_major=120, n_minor=60))
    argv = ["render", str(tmp_path / "scene.ply"), "-o", str(tmp_path / "views"), "--views", "200", "--width", "256"]
    repo = Path(__file__).resolve().parents[1]
    with subprocess.Popen(
        [sys.executable, "-m", "gt2gs_blender", *argv, "--backend", "torch"],
        cwd=repo,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    ) as command:
        deadline = time.monotonic() + 120
        while not list(tmp_path.glob("views/.*.tmp")) and command.poll() is None and time.monotonic() < deadline:
            time.sleep(0.02)
        command.send_signal(signum)
        _, err = command.communicate(timeout=60)
    assert command.returncode == 128 + signum, err
    assert err.strip().splitlines()[-1] == f"gt2gs: error: stopped by {signal.Signals(signum).name}"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.ply"]


def test_a_signal_the_moment_a_temp_file_is_made_leaves_nothing(tmp_path, monkeypatch):
    """A stop signal handled right after the temp file was created (where the SIGHUP test above once left its views
    folder behind, a temp file in it): the temp file goes, and with it the folder made for the outputs."""
    real_open = os.open

    def open_then_stopped(*args, **kwargs):
        real_open(*args, **kwargs)
        raise KeyboardInterrupt

    out = tmp_path / "views"
    monkeypatch.setattr(atomic.os, "open", open_then_stopped)
    with pytest.raises(KeyboardInterrupt), atomic.all_or_nothing([out / "view.png"], new_folders=[out]):
        atomic.atomic_write(out / "view.png", b"data")
    assert list(tmp_path.iterdir()) == []


def test_a_file_that_already_has_the_temp_files_name_is_not_removed(tmp_path, monkeypatch):
    """O_EXCL refuses a temp name that is taken; that file is someone else's, so the failure leaves it."""
    monkeypatch.setattr(atomic.secrets, "token_hex", lambda n: "0" * (2 * n))
    taken = tmp_path / ".out.ply.00000000.tmp"
    taken.write_bytes(b"theirs")
    with pytest.raises(FileExistsError):
        atomic.atomic_write(tmp_path / "out.ply", b"data")
    assert taken.read_bytes() == b"theirs" and not (tmp_path / "out.ply").exists()


def test_atomic_errors_name_the_target_never_the_temp_file(tmp_path):
    for target in (tmp_path / "no" / "out.ply", Path("/proc/gt2gs-out.ply")):
        with pytest.raises(OSError) as caught:
            atomic.atomic_write(target, b"data")
        assert caught.value.filename == str(target) and ".tmp" not in str(caught.value)


def test_atomic_write_takes_a_name_near_the_limit(tmp_path):
    target = tmp_path / ("y" * 250 + ".ply")
    atomic.atomic_write(target, b"data")
    assert [p.name for p in tmp_path.iterdir()] == [target.name]


def test_check_outputs_names_the_users_path(tmp_path):
    source = tmp_path / "in.ply"
    source.write_bytes(b"x")
    with pytest.raises(InputFileError, match="would overwrite the scene") as caught:
        atomic.check_outputs([("OUT", tmp_path / "." / "in.ply")], [("scene", source)])
    assert caught.value.path == str(tmp_path / "in.ply")
    atomic.check_outputs([("OUT", tmp_path / "new.ply")], [("scene", source), ("absent", None)])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.ply"]
