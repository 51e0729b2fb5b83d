"""Issue 37's frontier: what one setting trades between the scene a result keeps and the texture the measure finds.

``python bench/frontier.py --lever keep_scene --runs 0=TAG 0.3=TAG ... [--default 0.85] [--scenes donut fern]
[--name NAME]``

Each ``VALUE=TAG`` names a ``bench/recognise.py`` output (``bench/out/recognise/<TAG>.json``, ``{scene}`` in a tag is
replaced by each scene's name) run with the lever at that value and everything else at the default. Per scene and
value: how many textures are found (top 3 under both measures), the mean rank over both measures and all textures
(1 = every texture ranked first of the ten), the mean and the least content SSIM to the original over the textures
(over the object's pixels, the fern's frame) and the seconds a transfer took. The default run's calibration rows
are drawn beside the lever as reference points: the texture alone on the exact surface (``layout-surface``: no
splats, nothing of the scene kept, the measure's ceiling for a texture laid on this scene), the run's own target
(``layout-target``), its start (``layout-start``), the texture projected flat in screen space (``projected-64``)
and the untouched scene.

Nothing here runs a transfer. Prints a table, writes bench/out/<NAME>.json and .png (``frontier_<lever>`` unless
named; one panel per scene: content across, mean rank up, the lever's values joined in order).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from statistics import mean
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

sys.path.insert(0, str(Path(__file__).resolve().parent))
from recognise import MEASURES, OUT, TOP, is_transfer, summarise

REFERENCES = {
    "layout-surface": "texture alone on the exact surface",
    "layout-target": "the run's target (exact surface, scene kept)",
    "layout-start": "the run's start (splats, before optimising)",
    "projected-64": "texture flat in screen space",
    "original": "the scene untouched",
}
"""Calibration rows drawn as reference points, and what each is to a reader."""
CONTENT_NEEDED = {"fern": 0.51}
"""Issue 37's content target per scene (the paper's frame SSIM on the fern), drawn as a line; 0.5 elsewhere."""


def summary(rows: list[dict]) -> dict[str, Any]:
    """Found count, mean rank over both measures, mean and least content (the texture that keeps the least of the
    scene, which the mean hides) and seconds of one variant's rows, found and content as ``bench/recognise.py``
    summarises them."""
    (variants,) = summarise(rows).values()
    (counted,) = variants.values()
    seconds = [r["seconds"] for r in rows if r.get("seconds") is not None]
    return {
        "textures": counted["n"],
        "found": counted[f"top{TOP}_both"],
        "mean_rank": mean(r[f"{m}_rank"] for r in rows for m in MEASURES),
        "content": counted["mean_content_ssim"],
        "content_min": counted["least_content_ssim"],
        "seconds": [min(seconds), max(seconds)] if seconds else None,
    }


def lever_point(path: Path, scene: str) -> dict[str, Any]:
    """The transfer rows of ``scene`` in a recognise output, summarised (one preset and seed per output)."""
    rows = [r for r in json.loads(path.read_text())["rows"] if r["scene"] == scene and is_transfer(r["variant"])]
    if not rows:
        raise SystemExit(f"{path}: no transfer rows for {scene}; run bench/recognise.py with a preset first")
    if len({r["variant"] for r in rows}) != 1:
        raise SystemExit(f"{path}: several presets or seeds for {scene}; give one run (preset and seed) per value")
    return summary(rows)


def reference_points(path: Path, scene: str) -> dict[str, dict[str, Any]]:
    """The calibration rows of ``scene`` in a recognise output, summarised per variant in ``REFERENCES``."""
    rows = [r for r in json.loads(path.read_text())["rows"] if r["scene"] == scene]
    return {
        v: summary([r for r in rows if r["variant"] == v]) for v in REFERENCES if any(r["variant"] == v for r in rows)
    }


def plot(lever: str, default: str | None, points: dict, references: dict, path: Path) -> None:
    """One panel per scene: content across, mean rank up (best at the top), the lever's values joined in order."""
    scenes = list(points)
    fig, axes = plt.subplots(1, len(scenes), figsize=(6.0 * len(scenes), 5.0), squeeze=False)
    markers = dict(zip(REFERENCES, "*sD^x"))
    for ax, scene in zip(axes[0], scenes):
        values = list(points[scene])
        xs = [points[scene][v]["content"] for v in values]
        ys = [points[scene][v]["mean_rank"] for v in values]
        ax.plot(xs, ys, "-o", color="tab:blue", label=f"{lever} (label: value, found of 6)")
        for i, (v, x, y) in enumerate(zip(values, xs, ys)):
            bold = "bold" if v == default else "normal"
            offset = (6, 6) if i % 2 else (-6, -14)  # alternate sides: neighbouring values may share a rank
            label = f"{v}: {points[scene][v]['found']}"
            ax.annotate(label, (x, y), textcoords="offset points", xytext=offset, fontweight=bold)
        ax.axvline(CONTENT_NEEDED.get(scene, 0.5), color="tab:red", ls="--", lw=1, label="content asked (issue 37)")
        for variant, ref in references[scene].items():
            ax.plot(
                ref["content"],
                ref["mean_rank"],
                markers[variant],
                color="0.35",
                ls="none",
                label=f"{REFERENCES[variant]} ({ref['found']})",
            )
        ax.set(
            title=scene,
            xlabel="content: SSIM to the original (held-out views)",
            ylabel="mean rank of the texture among 10 (Gram and Gabor)",
        )
        ax.invert_yaxis()
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def print_table(lever: str, points: dict, references: dict) -> None:
    """Per scene, the lever's values and then the reference rows."""
    print(f"{'scene':7} {lever + ' / reference':46} {'found':>6} {'mean rank':>9} {'content':>8} {'least':>6}  seconds")
    for scene in points:
        for label, s in [*points[scene].items(), *((REFERENCES[v], r) for v, r in references[scene].items())]:
            secs = "" if s["seconds"] is None else f"{s['seconds'][0]:.0f}-{s['seconds'][1]:.0f}"
            found = f"{s['found']}/{s['textures']}"
            line = f"{scene:7} {label:46} {found:>6} {s['mean_rank']:9.2f} {s['content']:8.3f} {s['content_min']:6.3f}"
            print(f"{line}  {secs}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--lever", required=True, help="the setting the runs vary (a TransferConfig name)")
    parser.add_argument("--runs", nargs="+", required=True, metavar="VALUE=TAG", help="in the lever's order")
    parser.add_argument("--default", help="the lever's default value (drawn bold); its run gives the references")
    parser.add_argument("--scenes", nargs="+", default=["donut", "fern"])
    parser.add_argument("--name", help="output name under bench/out (default: frontier_<lever>)")
    args = parser.parse_args()
    runs = dict(pair.split("=", 1) for pair in args.runs)
    reference_tag = runs.get(args.default, next(iter(runs.values())))
    points = {
        s: {v: lever_point(OUT / f"{tag.format(scene=s)}.json", s) for v, tag in runs.items()} for s in args.scenes
    }
    references = {s: reference_points(OUT / f"{reference_tag.format(scene=s)}.json", s) for s in args.scenes}
    print_table(args.lever, points, references)
    stem = OUT.parent / (args.name or f"frontier_{args.lever}")
    stem.with_suffix(".json").write_text(
        json.dumps(
            {"lever": args.lever, "runs": runs, "default": args.default, "points": points, "references": references},
            indent=1,
        )
    )
    plot(args.lever, args.default, points, references, stem.with_suffix(".png"))
    print(f"wrote {stem}.json and {stem}.png")


if __name__ == "__main__":
    main()
