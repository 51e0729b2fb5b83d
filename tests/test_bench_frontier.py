"""bench/frontier.py: a lever's points and the reference rows, summarised from bench/recognise.py's rows."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.frontier import lever_point, reference_points


def rank_row(texture: str, variant: str, gram: int, gabor: int, content: float, seconds: float | None = None) -> dict:
    """One row as bench/recognise.py writes it (the fields the frontier reads)."""
    return {
        "scene": "donut",
        "texture": texture,
        "variant": variant,
        "gram_rank": gram,
        "gabor_rank": gabor,
        "content_ssim": content,
        "seconds": seconds,
    }


def write_rows(path: Path, rows: list[dict]) -> Path:
    path.write_text(json.dumps({"rows": rows}))
    return path


def test_a_lever_point_counts_textures_top_3_under_both_and_averages_every_rank(tmp_path: Path) -> None:
    """Found = top 3 under Gram and Gabor (1/3 and 3/3 count, 2/4 does not); the mean rank is over both measures
    and all textures; calibration rows and other scenes are left out of the run's point."""
    rows = [
        rank_row("a", "fast-s0", 1, 3, 0.6, 30.0),
        rank_row("b", "fast-s0", 2, 4, 0.5, 34.0),
        rank_row("c", "fast-s0", 3, 3, 0.7, 31.0),
        rank_row("a", "layout-surface", 1, 1, 0.1),
        rank_row("b", "layout-surface", 9, 1, 0.2),
        rank_row("a", "original", 10, 10, 1.0),
        {**rank_row("a", "fast-s0", 10, 10, 0.0, 99.0), "scene": "fern"},
    ]
    path = write_rows(tmp_path / "run.json", rows)
    point = lever_point(path, "donut")
    assert point["textures"] == 3 and point["found"] == 2
    assert point["mean_rank"] == pytest.approx((1 + 3 + 2 + 4 + 3 + 3) / 6)
    assert point["content"] == pytest.approx(0.6) and point["content_min"] == pytest.approx(0.5)
    assert point["seconds"] == [30.0, 34.0]
    refs = reference_points(path, "donut")
    assert set(refs) == {"layout-surface", "original"}
    assert refs["layout-surface"]["found"] == 1 and refs["layout-surface"]["seconds"] is None
    assert refs["original"]["mean_rank"] == 10


def test_a_lever_point_refuses_a_run_of_several_presets_or_seeds(tmp_path: Path) -> None:
    rows = [rank_row("a", "fast-s0", 1, 1, 0.6, 30.0), rank_row("a", "fast-s1", 2, 2, 0.6, 30.0)]
    with pytest.raises(SystemExit, match="several presets or seeds"):
        lever_point(write_rows(tmp_path / "run.json", rows), "donut")
