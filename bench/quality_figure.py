"""docs/quality.md's picture: texture | original | preview | result, a row per scene and texture, from a
bench/recognise.py run's saved held-out views and its measures.

    .venv/bin/python bench/recognise.py --scenes fern donut guitar playbot --textures herringbone_wood brick_wall \\
        --presets fast --tag s27-figure
    .venv/bin/python bench/quality_figure.py --tag s27-figure [--view 0] [--out docs/quality_sheet.jpg]

or from several runs' rows of some of their textures, a run's scenes in the order the tags are given:

    .venv/bin/python bench/quality_figure.py --tag s41-hues05-fern s41-hues05 s41-hues05-robot \
        --textures herringbone_wood brick_wall

The preview is the layout start (what *Preview Orientation* shows), the result the run's; both, and the original,
from the same held-out view the run never optimised. Under each result: its structure ranks among the ten
textures (G: Gram, B: Gabor; found when both are top 3) and its content (luminance SSIM over the object's pixels).
The textures and the view are chosen on the command line, not by their numbers.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))

from recognise import OUT, TOP, texture_path, tile
from recognise_scenes import CAPTURES

FIGURE = ROOT / "docs" / "quality_sheet.jpg"
QUALITY = 80
SIDE = 240
"""Each cell's side in pixels (a credit line fits under it)."""


def picture(folder: Path, name: str) -> np.ndarray:
    """A saved held-out view (RGB uint8); a clear error naming the file when the run did not save it."""
    path = folder / f"{name}.png"
    image = cv2.imread(str(path))
    if image is None:
        raise SystemExit(f"{path}: no such picture; run bench/recognise.py with this tag first (see --help)")
    return cv2.cvtColor(image, cv2.COLOR_BGR2RGB)


def credit(scene: str) -> str:
    """The original's label: the scene, with its title, author and licence when its folder has a CREDITS.txt (the
    robot is CC-BY-4.0: credit it wherever it is shown)."""
    folder = CAPTURES.get(scene)
    credits = folder / "CREDITS.txt" if folder is not None else None
    if credits is None or not credits.is_file():
        return scene
    fields = dict(line.lstrip("* ").split(":", 1) for line in credits.read_text().splitlines() if ":\t" in line)
    author = fields.get("author", "").split("(")[0].strip()
    licence = fields.get("license type", "").split("(")[0].strip()
    return f"{fields.get('title', scene).strip()}, {author}, {licence}"


def result_label(row: dict) -> str:
    """'found G1 B2 · SSIM 0.62' for a result row (found: top ``TOP`` under both measures)."""
    found = "found" if max(row["gram_rank"], row["gabor_rank"]) <= TOP else "not found"
    return f"{found} G{row['gram_rank']} B{row['gabor_rank']} SSIM {row['content_ssim']:.2f}"


def figure_rows(
    report: dict, variant: str, view: int, out: Path = OUT, textures: list[str] | None = None
) -> list[np.ndarray]:
    """One strip per (scene, texture) result of ``variant`` in ``report`` (its pictures under ``out``/<tag>), of
    ``textures`` only when given: texture | original | preview | result."""
    strips = []
    for row in report["rows"]:
        if row["variant"] != variant or (textures is not None and row["texture"] not in textures):
            continue
        scene, texture = row["scene"], row["texture"]
        folder = out / report["tag"] / scene
        photo = cv2.cvtColor(cv2.imread(str(texture_path(texture))), cv2.COLOR_BGR2RGB)
        preview = report["scenes"][scene]["preview"][variant.rsplit("-s", 1)[0]]["reference"]
        strips.append(
            np.hstack(
                [
                    tile(photo, texture.replace("_", " "), SIDE),
                    tile(picture(folder, f"original-v{view}"), credit(scene), SIDE),
                    tile(picture(folder, f"{texture}-{preview}-v{view}"), "preview", SIDE),
                    tile(picture(folder, f"{texture}-{variant}-v{view}"), result_label(row), SIDE),
                ]
            )
        )
    if not strips:
        raise SystemExit(f"{report['tag']}: no {variant!r} results (variants are <preset>-s<seed>)")
    return strips


def report(tag: str) -> dict:
    """The bench/recognise.py report of ``tag``; a clear error naming its file when there is none."""
    path = OUT / f"{tag}.json"
    if not path.is_file():
        raise SystemExit(f"{path}: no such report; run bench/recognise.py --tag {tag} first")
    return json.loads(path.read_text())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tag", nargs="+", required=True, help="bench/recognise.py runs' tags, drawn in this order")
    parser.add_argument("--textures", nargs="+", help="draw only these textures (default: every one a run has)")
    parser.add_argument("--variant", default="fast-s0", help="which results: <preset>-s<seed> (default fast-s0)")
    parser.add_argument("--view", type=int, default=0, help="which held-out view (default 0)")
    parser.add_argument("--out", type=Path, default=FIGURE)
    args = parser.parse_args()
    image = np.vstack(
        [strip for tag in args.tag for strip in figure_rows(report(tag), args.variant, args.view, OUT, args.textures)]
    )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    ok, data = cv2.imencode(".jpg", cv2.cvtColor(image, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, QUALITY])
    if not ok:
        raise SystemExit(f"{args.out}: could not encode the picture")
    args.out.write_bytes(data.tobytes())
    print(f"wrote {args.out} ({image.shape[1]} x {image.shape[0]} px, {len(data) / 1024:.0f} KiB)")


if __name__ == "__main__":
    main()
