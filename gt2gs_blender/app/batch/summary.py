"""A batch's summary: one row per job (status, attempts, time, the one-line error, the content and structure
numbers from its report) as CSV and as a Markdown table. Pure Python: Blender's batch script writes it too."""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ...core.atomic import atomic_write
from .manifest import Job

SUMMARY_CSV, SUMMARY_MD = "summary.csv", "summary.md"
MEASURES = {
    "object_ssim": "content",
    "object_ssim_blurred": "structure",
    "texture_match": "texture match",
}
"""The report's numbers the summary shows, with their column titles: content = SSIM to the original over the
object, structure = the same at the object's scale, texture match = distance to the texture (lower is closer)."""
STATUSES = ("done", "kept", "failed", "cancelled")
"""done: run now; kept: finished by an earlier run with the same settings (--resume); failed: its error says
why; cancelled: not run (the batch was interrupted)."""


@dataclass
class Row:
    """One job's line in the summary."""

    job: Job
    status: str
    attempts: int = 0
    seconds: float = 0.0
    error: str = ""
    report: dict[str, Any] = field(default_factory=dict)

    def measures(self) -> dict[str, float | None]:
        """The report's content, structure and texture numbers (None: not measured; the preview preset
        measures nothing)."""
        metrics = self.report.get("metrics") or {}
        return {title: metrics.get(key) for key, title in MEASURES.items()}

    def cells(self) -> dict[str, str]:
        """The row as the table's text cells."""
        settings = " ".join(f"{k}={_number(v)}" for k, v in sorted(self.job.settings.items()))
        cells = {
            "job": self.job.name,
            "status": self.status,
            "attempts": str(self.attempts),
            "seconds": f"{self.seconds:.1f}" if self.seconds else "",
            "scene": str(self.job.scene),
            "texture": str(self.job.texture),
            "preset": self.job.preset,
            "settings": settings,
            "gaussians": str(self.report.get("n_gaussians", "")),
        }
        cells.update({title: "" if v is None else f"{v:.4f}" for title, v in self.measures().items()})
        cells["result"] = f"{self.job.name}/{self.job.output}" if self.status in ("done", "kept") else ""
        cells["error"] = self.error
        return cells


def write_summary(out: Path, rows: list[Row]) -> list[Path]:
    """Write ``summary.csv`` and ``summary.md`` (atomically) into ``out``; their paths."""
    cells = [row.cells() for row in rows]
    header = list(cells[0]) if cells else []
    table = io.StringIO()
    writer = csv.DictWriter(table, header, lineterminator="\n")
    writer.writeheader()
    writer.writerows(cells)
    paths = [out / SUMMARY_CSV, out / SUMMARY_MD]
    atomic_write(paths[0], table.getvalue())
    atomic_write(paths[1], markdown(rows, header, cells))
    return paths


def markdown(rows: list[Row], header: list[str], cells: list[dict[str, str]]) -> str:
    """The summary as a Markdown table under a one-line count."""
    lines = [f"# Batch: {len(rows)} jobs, {counts(rows)}", "", "| " + " | ".join(header) + " |"]
    lines.append("|" + "|".join("---" for _ in header) + "|")
    lines += ["| " + " | ".join(c[h].replace("|", "\\|") for h in header) + " |" for c in cells]
    return "\n".join(lines) + "\n"


def counts(rows: list[Row]) -> str:
    """'3 done, 1 failed' of the rows."""
    return ", ".join(f"{sum(r.status == s for r in rows)} {s}" for s in STATUSES if any(r.status == s for r in rows))


def _number(value: Any) -> str:
    return f"{value:g}" if isinstance(value, float) else str(value)
