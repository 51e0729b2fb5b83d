"""Interactive latencies the issue budgets, timed here instead of asserted in the tests.

* orientation preview: one 256 px ``orientation_preview`` of the 100 x 100 wall the test renders,
  after a first call that builds or loads the rasterizer (budget 2 s on the CPU);
* worker cancel: ``Job.cancel()`` on a transfer worker in its stylise loop, until the job reads
  CANCELLED (budget 5 s, the job's grace period before it kills the worker).

The scenes and job set-up are the tests' own (tests/test_orientation_preview.py, tests/test_worker.py).
Prints a table and writes JSON records {name, repeats, median_s, min_s, max_s, budget_s, within_budget}.

    python bench/latency.py                       # 5 previews, 2 cancels
    python bench/latency.py --repeats 10 --cancels 3 --json out.json
"""

from __future__ import annotations

import argparse
import functools
import json
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from gt2gs_blender.blender.job import CANCELLED
from gt2gs_blender.core.transfer.orientation_preview import orientation_preview
from tests.test_orientation_preview import front_camera, horizontal_stripes, wall
from tests.test_worker import job_with_inputs, transfer_spec, wait_for

PREVIEW_BUDGET_S = 2.0
CANCEL_BUDGET_S = 5.0
DEFAULT_JSON = ROOT / "bench" / "out" / "latency.json"


def preview_seconds(repeats: int) -> list[float]:
    """Seconds per 256 px orientation preview of the test wall, after one warm-up call."""
    scene, cam, stripes = wall(100), front_camera(), horizontal_stripes()
    orientation_preview(scene, stripes, cam, 0.0)  # builds / loads the rasterizer once
    return [timed(functools.partial(orientation_preview, scene, stripes, cam, 45.0 + i)) for i in range(repeats)]


def cancel_seconds(repeats: int) -> list[float]:
    """Seconds from ``Job.cancel()`` to a CANCELLED job, each on a fresh worker mid-stylise."""
    return [one_cancel() for _ in range(repeats)]


def one_cancel() -> float:
    """Start a long transfer job, wait for its stylise loop, time the cancel; the job is cleaned up."""
    job = job_with_inputs()
    try:
        with tempfile.TemporaryDirectory() as banks:
            job.start(transfer_spec(Path(banks), stylise_steps=400))
            wait_for(job, lambda s: s.stage == "stylise" and s.step >= 2)
            seconds = timed(job.cancel)
            if job.status.state != CANCELLED:
                raise RuntimeError(f"cancel left the job {job.status.state}")
            return seconds
    finally:
        job.cleanup()


def timed(call: Callable[[], object]) -> float:
    """Wall-clock seconds of one call."""
    start = time.perf_counter()
    call()
    return time.perf_counter() - start


def record(name: str, seconds: list[float], budget_s: float) -> dict:
    """The JSON record of one measured latency."""
    median = statistics.median(seconds)
    return {
        "name": name,
        "repeats": len(seconds),
        "median_s": median,
        "min_s": min(seconds),
        "max_s": max(seconds),
        "budget_s": budget_s,
        "within_budget": max(seconds) <= budget_s,
    }


def table(records: list[dict]) -> str:
    """The records as a fixed-width text table."""
    lines = [f"{'latency':<22}{'n':>3}{'median s':>10}{'min s':>8}{'max s':>8}{'budget s':>10}  ok"]
    for r in records:
        lines.append(
            f"{r['name']:<22}{r['repeats']:>3}{r['median_s']:>10.3f}{r['min_s']:>8.3f}{r['max_s']:>8.3f}"
            f"{r['budget_s']:>10.1f}  {'yes' if r['within_budget'] else 'NO'}"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Measure, print the table, write the JSON; exit status 1 when a latency is over its budget."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5, help="timed orientation previews")
    parser.add_argument("--cancels", type=int, default=2, help="timed worker cancels (one worker each)")
    parser.add_argument("--json", type=Path, default=DEFAULT_JSON, help=f"output (default {DEFAULT_JSON})")
    args = parser.parse_args(argv)
    records = [
        record("orientation preview", preview_seconds(args.repeats), PREVIEW_BUDGET_S),
        record("worker cancel", cancel_seconds(args.cancels), CANCEL_BUDGET_S),
    ]
    print(table(records))
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(records, indent=1) + "\n", encoding="utf-8")
    print(f"wrote {args.json}")
    return 0 if all(r["within_budget"] for r in records) else 1


if __name__ == "__main__":
    sys.exit(main())
