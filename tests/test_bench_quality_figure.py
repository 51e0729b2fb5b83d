"""bench/quality_figure.py: docs/quality.md's picture drawn from a bench/recognise.py run's pictures and rows."""

from __future__ import annotations

import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.quality_figure import SIDE, credit, figure_rows, result_label

from .conftest import SHARED


def test_the_robot_is_credited_from_its_own_credits_file_and_a_scene_without_one_by_its_name():
    if not (SHARED / "data" / "scenes" / "captures" / "playbot" / "CREDITS.txt").is_file():
        pytest.skip("the shared captures are not here")
    assert credit("playbot") == "PLAYBOT, Stephane Agullo, CC-BY-4.0"
    assert credit("donut") == "donut"


def test_a_result_is_found_only_when_both_measures_rank_it_top_three():
    row = {"gram_rank": 3, "gabor_rank": 3, "content_ssim": 0.6149}
    assert result_label(row) == "found G3 B3 SSIM 0.61"
    assert result_label({**row, "gabor_rank": 4}).startswith("not found G3 B4")


def test_each_result_is_a_strip_of_texture_original_preview_and_result_from_one_view(tmp_path):
    folder = tmp_path / "t" / "donut"
    folder.mkdir(parents=True)
    colours = {"original-v1": 40, "brick_wall-layout-start-v1": 120, "brick_wall-fast-s0-v1": 200}
    for name, grey in colours.items():
        cv2.imwrite(str(folder / f"{name}.png"), np.full((64, 96, 3), grey, np.uint8))
    rows = [
        {"scene": "donut", "texture": "brick_wall", "variant": v, "gram_rank": 1, "gabor_rank": 2, "content_ssim": 0.5}
        for v in ("fast-s0", "fast-s1")
    ]
    report = {"tag": "t", "rows": rows, "scenes": {"donut": {"preview": {"fast": {"reference": "layout-start"}}}}}
    (strip,) = figure_rows(report, "fast-s0", 1, tmp_path)
    assert strip.shape == (SIDE, 4 * SIDE, 3)
    middle = SIDE // 2
    assert [int(strip[middle, k * SIDE + middle, 0]) for k in (1, 2, 3)] == list(colours.values())
    with pytest.raises(SystemExit, match=r"original-v0\.png: no such picture"):
        figure_rows(report, "fast-s0", 0, tmp_path)


def test_only_the_textures_asked_for_are_drawn(tmp_path):
    folder = tmp_path / "t" / "donut"
    folder.mkdir(parents=True)
    rows = []
    for grey, texture in ((60, "brick_wall"), (180, "honeycomb")):
        for name in ("original-v0", f"{texture}-layout-start-v0", f"{texture}-fast-s0-v0"):
            cv2.imwrite(str(folder / f"{name}.png"), np.full((64, 96, 3), grey, np.uint8))
        ranks = {"gram_rank": 1, "gabor_rank": 1, "content_ssim": 0.5}
        rows.append({"scene": "donut", "texture": texture, "variant": "fast-s0", **ranks})
    report = {"tag": "t", "rows": rows, "scenes": {"donut": {"preview": {"fast": {"reference": "layout-start"}}}}}
    assert len(figure_rows(report, "fast-s0", 0, tmp_path)) == 2
    (strip,) = figure_rows(report, "fast-s0", 0, tmp_path, ["honeycomb"])
    assert int(strip[SIDE // 2, 3 * SIDE + SIDE // 2, 0]) == 180
