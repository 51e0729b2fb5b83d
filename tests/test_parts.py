"""Parts of a scene from its splats' colour and position (``core.scene.parts``)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch

from gt2gs_blender.core.scene.gaussians import GaussianScene
from gt2gs_blender.core.scene.parts import MIN_SHARE, find_parts, srgb_to_lab

ROOT = Path(__file__).resolve().parents[1]


def box(rng: np.random.Generator, lo: list[float], hi: list[float], rgb: list[float], n: int) -> tuple[np.ndarray, ...]:
    """``n`` splat centres filling a box, each of colour ``rgb`` give or take a little noise."""
    points = rng.uniform(lo, hi, size=(n, 3))
    colours = np.clip(np.asarray(rgb) + rng.normal(scale=0.02, size=(n, 3)), 0.0, 1.0)
    return points, colours


def scene_of(*boxes: tuple[np.ndarray, np.ndarray], units: float = 1.0) -> GaussianScene:
    """The boxes' splats, every length times ``units``."""
    points = torch.tensor(np.concatenate([b[0] for b in boxes]) * units, dtype=torch.float32)
    colours = torch.tensor(np.concatenate([b[1] for b in boxes]), dtype=torch.float32)
    n = len(points)
    return GaussianScene.from_activated(
        means=points, scales=torch.full((n, 3), 0.01 * units), opacities=torch.full((n,), 0.9), colors=colours
    )


@pytest.mark.parametrize("units", [1.0, 100.0, 0.01])
def test_two_touching_objects_of_unlike_colour_are_two_parts(units: float) -> None:
    """A dark stand touching a light body (boxes sharing a face): two parts, each holding exactly its box's splats,
    the larger first, with its colour, whatever units the capture is in."""
    rng = np.random.default_rng(0)
    body = box(rng, [0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [0.85, 0.7, 0.4], 6000)
    stand = box(rng, [0.0, 0.0, -0.5], [1.0, 1.0, 0.0], [0.08, 0.08, 0.1], 3000)
    parts = find_parts(scene_of(body, stand, units=units))
    assert len(parts) == 2
    np.testing.assert_array_equal(parts.labels, np.r_[np.zeros(6000, int), np.ones(3000, int)])
    np.testing.assert_allclose(parts.colours[0], [0.85, 0.7, 0.4], atol=0.02)
    assert parts.mask(1).sum() == 3000
    with pytest.raises(IndexError, match="parts 0 to 1"):
        parts.mask(2)


def test_one_colour_with_a_gradual_shade_is_one_part() -> None:
    """One object whose colour darkens smoothly along its length (a shaded surface, no boundary): one part; two
    same-coloured touching boxes too; a floater far off joins the nearest part rather than making its own."""
    rng = np.random.default_rng(1)
    points = rng.uniform(0.0, 1.0, size=(8000, 3)) * [3.0, 1.0, 1.0]
    shaded = np.clip(np.outer(1.0 - 0.12 * points[:, 0], [0.8, 0.5, 0.3]), 0.0, 1.0)  # 1 to 0.64
    floater = (np.array([[9.0, 9.0, 9.0]]), np.array([[0.0, 1.0, 0.0]]))
    parts = find_parts(scene_of((points, shaded), floater))
    assert len(parts) == 1 and parts.sizes.tolist() == [8001]


def test_a_part_smaller_than_the_least_share_joins_its_neighbour() -> None:
    """A red speck of a few splats on a grey block (under ``MIN_SHARE`` of the splats) is not a part of its own."""
    rng = np.random.default_rng(2)
    block = box(rng, [0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [0.5, 0.5, 0.5], 5000)
    speck_count = int(MIN_SHARE * 5000) // 2
    speck = box(rng, [0.45, 0.45, 1.0], [0.55, 0.55, 1.02], [0.9, 0.1, 0.1], speck_count)
    assert len(find_parts(scene_of(block, speck))) == 1


def test_an_empty_scene_has_no_parts() -> None:
    empty = scene_of((np.zeros((0, 3)), np.zeros((0, 3))))
    parts = find_parts(empty)
    assert len(parts) == 0 and parts.labels.shape == (0,)


def test_the_command_line_lists_parts_and_restyles_one(tmp_path, capsys) -> None:
    """``parts`` lists a two-part file largest first with its colours; ``transfer --part 7`` on it is one line
    naming the file and the parts there are, before any work."""
    from gt2gs_blender.app.cli.main import main
    from gt2gs_blender.core.api import write_ply

    rng = np.random.default_rng(0)
    scene = scene_of(
        box(rng, [0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [0.85, 0.7, 0.4], 3000),
        box(rng, [0.0, 0.0, -0.5], [1.0, 1.0, 0.0], [0.08, 0.08, 0.1], 1500),
    )
    path = tmp_path / "two.ply"
    write_ply(path, scene)
    assert main(["parts", str(path), "--json"]) == 0
    rows = __import__("json").loads(capsys.readouterr().out)
    assert [(r["part"], r["splats"]) for r in rows] == [(0, 3000), (1, 1500)]
    assert rows[1]["colour"] == "#141419"
    texture = tmp_path / "t.png"
    __import__("cv2").imwrite(str(texture), rng.integers(0, 256, size=(256, 256, 3), dtype=np.uint8))
    assert main(["transfer", str(path), str(texture), "--part", "7", "-o", str(tmp_path / "out.ply")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(path) in err[0] and "parts 0 to 1" in err[0]
    assert not (tmp_path / "out.ply").exists()


def test_lab_is_opencvs() -> None:
    """The numpy sRGB to CIE Lab agrees with OpenCV's float ``COLOR_RGB2Lab`` (whose gamma is a table: within a
    Lab unit, a fifth of a just-noticeable difference), black and white exactly."""
    rgb = np.random.default_rng(3).uniform(0.0, 1.0, size=(20000, 3)).astype(np.float32)
    rgb[:2] = [[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]]
    reference = cv2.cvtColor(rgb.reshape(-1, 1, 3), cv2.COLOR_RGB2Lab).reshape(-1, 3)
    lab = srgb_to_lab(rgb)
    assert np.abs(lab - reference).max() < 1.0 and np.abs(lab - reference).mean() < 0.1
    np.testing.assert_allclose(lab[:2], [[0.0, 0.0, 0.0], [100.0, 0.0, 0.0]], atol=0.01)


def test_blender_finds_the_same_parts_without_torch_or_opencv(tmp_path) -> None:
    """Blender's Python has neither: ``find_parts_in`` on a file's numpy arrays, in a process where both are
    blocked, labels the splats as ``find_parts`` does on the same file's torch scene."""
    from gt2gs_blender.core.api import read_scene, write_ply

    rng = np.random.default_rng(0)
    scene = scene_of(
        box(rng, [0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [0.85, 0.7, 0.4], 1500),
        box(rng, [0.0, 0.0, -0.5], [1.0, 1.0, 0.0], [0.08, 0.08, 0.1], 700),
        box(rng, [1.0, 0.0, 0.0], [1.5, 1.0, 1.0], [0.2, 0.5, 0.9], 600),
    )
    path, labels = tmp_path / "three.ply", tmp_path / "labels.npy"
    write_ply(path, scene)
    code = (
        "import sys; sys.modules['torch'] = sys.modules['cv2'] = None\n"
        "import numpy as np\n"
        "from gt2gs_blender.core.scene.parts import find_parts_in\n"
        "from gt2gs_blender.core.scene.ply import read_ply_arrays\n"
        f"np.save({str(labels)!r}, find_parts_in(read_ply_arrays({str(path)!r})).labels)\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-2000:]
    expected = find_parts(read_scene(path)).labels
    assert len(np.unique(expected)) == 3
    np.testing.assert_array_equal(np.load(labels), expected)
