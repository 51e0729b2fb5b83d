"""A batch's contact sheet: every job's result as its before/after strip's first stylised view, the texture in a
corner, and under it the job's name, its content and structure numbers, or its error."""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np

from ..images import write_png
from ..jobs import STRIP_SIZE
from .outputs import folder
from .summary import Row

CONTACT_SHEET = "contact_sheet.png"
TILE = STRIP_SIZE
SWATCH = TILE // 4
TEXT_H = 54
COLUMNS = 6
FONT = cv2.FONT_HERSHEY_SIMPLEX
TEXT_W = TILE - 8
"""The text's width in a cell (4 px margins)."""
NAME_SCALES = (0.42, 0.36, 0.3)
"""The job's name at the largest of these it fits at (then wrapped, cut with '...')."""
NOTE_SCALE = 0.36


def write_contact_sheet(out: Path, rows: list[Row]) -> Path:
    """Write ``contact_sheet.png`` (atomically) into ``out``: a grid of one cell per job; its path."""
    cells = [_cell(out, row) for row in rows]
    columns = min(COLUMNS, max(1, len(cells)))
    grid = np.full((math.ceil(len(cells) / columns) * cells[0].shape[0], columns * TILE, 3), 255, np.uint8)
    for i, cell in enumerate(cells):
        y, x = (i // columns) * cell.shape[0], (i % columns) * TILE
        grid[y : y + cell.shape[0], x : x + TILE] = cell
    path = out / CONTACT_SHEET
    write_png(path, grid)
    return path


def _cell(out: Path, row: Row) -> np.ndarray:
    """One job's cell (RGB uint8): the result's first view with the texture swatch, then three lines of text."""
    cell = np.full((TILE + TEXT_H, TILE, 3), 255, np.uint8)
    strip = _read(folder(out, row.job).strip) if row.status in ("done", "kept") else None
    if strip is not None and strip.shape[0] >= 2 * TILE and strip.shape[1] >= 2 * TILE:
        cell[:TILE] = strip[TILE : 2 * TILE, TILE : 2 * TILE]  # the stylised row's first view
        cell[2 : 2 + SWATCH, 2 : 2 + SWATCH] = cv2.resize(strip[:TILE, :TILE], (SWATCH, SWATCH), cv2.INTER_AREA)
    else:
        cell[:TILE] = 235
    measures = row.measures()
    if row.error or row.status not in ("done", "kept"):
        numbers = f"{row.status}: {row.error}" if row.error else row.status
    elif measures["content"] is None:
        numbers = "not measured (the preset's Measure Result is off)"
    else:
        numbers = f"content {measures['content']:.3f}  structure {measures['structure']:.3f}"
    name_scale = next((scale for scale in NAME_SCALES if _width(row.job.name, scale) <= TEXT_W), NAME_SCALES[-1])
    _text(cell, wrapped(row.job.name, name_scale, 1)[0], TILE + 16, name_scale, (0, 0, 0))
    colour = (170, 0, 0) if row.status == "failed" else (40, 40, 40)
    for k, line in enumerate(wrapped(numbers, NOTE_SCALE, 2)):
        _text(cell, line, TILE + 34 + 16 * k, NOTE_SCALE, colour)
    return cell


def _read(path: Path) -> np.ndarray | None:
    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    return None if image is None else image[..., ::-1]


def _width(text: str, scale: float) -> int:
    """The pixel width of ``text`` at ``scale``."""
    return cv2.getTextSize(text, FONT, scale, 1)[0][0]


def wrapped(text: str, scale: float, lines: int) -> list[str]:
    """``text`` broken at spaces into at most ``lines`` lines that fit a cell at ``scale`` (a word longer than a
    line is cut); text left over ends the last line with '...', so nothing is cut mid-word unseen."""
    out: list[str] = []
    words, cut = text.split(), False
    while words and len(out) < lines and not cut:
        line = words.pop(0)
        while _width(line, scale) > TEXT_W:  # a word wider than a line: the rest of it is left over
            line, cut = line[:-1], True
        while words and not cut and _width(f"{line} {words[0]}", scale) <= TEXT_W:
            line += " " + words.pop(0)
        out.append(line)
    if words or cut:
        last = out[-1]
        while last and _width(last + "...", scale) > TEXT_W:
            last = last.rsplit(" ", 1)[0] if " " in last else last[:-1]
        out[-1] = last + "..."
    return out


def _text(cell: np.ndarray, text: str, y: int, scale: float, colour: tuple[int, int, int]) -> None:
    cv2.putText(cell, text, (4, y), FONT, scale, colour, 1, cv2.LINE_AA)
