"""bench/recognise.py's report under one tag filled one scene at a time: the earlier scenes stay when they ran with
the same settings, and other settings are refused with the file named (a second scene once silently replaced the
first's rows)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))

import recognise
import recognise_measure as measure


def run_args(scenes: list[str], **overrides: object) -> argparse.Namespace:
    """The arguments bench/recognise.py parses for ``scenes`` at `fast`, seed 0, with ``overrides`` (--set)."""
    return argparse.Namespace(
        scenes=scenes,
        presets=["fast"],
        seeds=[0],
        textures=list(recognise.STRUCTURED),
        projected_heights=[64, 128],
        size=recognise.HELD_OUT_SIZE,
        only_measure=False,
        overrides=dict(overrides),
    )


def rows_for(scene: str, found: int) -> list[dict]:
    """Six transfer rows for ``scene``, the first ``found`` textures ranked first under both measures."""
    return [
        {
            "scene": scene,
            "texture": texture,
            "variant": "fast-s0",
            "gram_rank": 1 if k < found else 7,
            "gabor_rank": 1 if k < found else 7,
            "content_ssim": 0.6 + 0.01 * k,
            "colour_specks": 0.05,
            "accent_shift": 20.0,
        }
        for k, texture in enumerate(recognise.STRUCTURED)
    ]


def write_report(path: Path, args: argparse.Namespace, rows: list[dict]) -> None:
    """A report as bench/recognise.py writes it, for ``args`` and ``rows``."""
    report = {
        "tag": path.stem,
        "args": {k: v for k, v in vars(args).items() if k != "overrides"},
        "overrides": args.overrides,
        "measure": measure.PARAMS,
        "scenes": {scene: {"held_out": ["orbit_001"]} for scene in args.scenes},
        "rows": rows,
        "summary": recognise.summarise(rows),
    }
    path.write_text(json.dumps(report, default=str))


def test_a_second_scene_under_the_tag_keeps_the_first(tmp_path: Path) -> None:
    path = tmp_path / "s-base.json"
    write_report(path, run_args(["guitar"]), rows_for("guitar", 2))
    kept = recognise.earlier_scenes(path, run_args(["playbot"]))
    assert list(kept["scenes"]) == ["guitar"]
    assert [r["texture"] for r in kept["rows"]] == list(recognise.STRUCTURED)
    summary = recognise.summarise(kept["rows"] + rows_for("playbot", 5))
    assert summary["guitar"]["fast-s0"]["top3_both"] == 2
    assert summary["playbot"]["fast-s0"]["top3_both"] == 5
    assert recognise.target_met(summary) == {"guitar/fast-s0": False, "playbot/fast-s0": True}


def test_the_same_scene_again_replaces_it(tmp_path: Path) -> None:
    path = tmp_path / "s-base.json"
    write_report(path, run_args(["guitar"]), rows_for("guitar", 2))
    assert recognise.earlier_scenes(path, run_args(["guitar"])) == {}
    assert recognise.earlier_scenes(path, run_args(["guitar"], keep_scene=0.6)) == {}
    assert recognise.earlier_scenes(tmp_path / "none.json", run_args(["guitar"])) == {}


def test_other_settings_under_the_tag_are_refused_with_the_file_named(tmp_path: Path) -> None:
    path = tmp_path / "s-base.json"
    write_report(path, run_args(["guitar"]), rows_for("guitar", 2))
    with pytest.raises(SystemExit, match=r"s-base\.json holds guitar measured with other overrides: use another --tag"):
        recognise.earlier_scenes(path, run_args(["playbot"], keep_scene=0.6))
    other_seeds = run_args(["playbot"])
    other_seeds.seeds = [1]
    with pytest.raises(SystemExit, match="other seeds"):
        recognise.earlier_scenes(path, other_seeds)


def test_the_summary_gives_the_saved_files_splats_and_older_reports_still_print(
    capsys: pytest.CaptureFixture[str],
) -> None:
    rows = rows_for("donut", 1)
    for k, r in enumerate(rows):
        r.update(seconds=10.0, splats=300_000 + 1_000 * k)
    older = rows_for("guitar", 0)  # measured before rows carried their splat count
    for r in older:
        r["seconds"] = 10.0
    summary = recognise.summarise(rows + older)
    assert summary["donut"]["fast-s0"]["mean_splats"] == pytest.approx(302_500)
    assert "mean_splats" not in summary["guitar"]["fast-s0"]
    recognise.print_table(rows + older, summary)
    lines = capsys.readouterr().out.splitlines()
    assert any(line.startswith("  donut") and line.endswith("splats 302,500") for line in lines)
    assert any(line.startswith("  guitar") and "splats" not in line for line in lines)


def test_the_summary_names_the_texture_nearest_to_flipping_from_rows_made_by_row():
    """Rows made by ``recognise.row`` from distances (seven others at 1.0-1.6, so the threshold is 1.2): one texture
    inside the top 3 by 20 % under Gram but 1 % under Gabor, one outside by 5 %, one far outside; the summary's
    nearest flip is the first, at its smaller margin, and a row without margins (an older report's) is passed over."""
    others = {f"other{k}": 1.0 + 0.1 * k for k in range(7)}

    def made(texture: str, gram: float, gabor: float) -> dict:
        at = {"gram": gram, "gabor": gabor}
        return recognise.row("s", texture, "fast-s0", {m: {**others, texture: at[m] * 1.2} for m in at})

    rows = [made("near", 0.8, 0.99), made("out", 1.05, 1.05), made("far", 2.5, 2.5), {**rows_for("s", 0)[0]}]
    assert (rows[0]["gram_rank"], rows[0]["gabor_rank"], rows[1]["gabor_rank"]) == (1, 3, 4)
    summary = recognise.summarise(rows)["s"]["fast-s0"]
    assert summary["nearest_flip_texture"] == "near"
    assert summary["nearest_flip"] == pytest.approx(0.01)
    assert recognise.decisive_margin(rows[1]) == pytest.approx(-0.05)
