"""Fit the shared LLFF fern at 1/8 resolution from random points and print held-out PSNR/SSIM and time.

One command: ``python bench/fit_fern.py [--iterations N] [--points N] [--sh-degree D]``; writes the
report to bench/out/fit_fern.json and the scene to bench/out/fit_fern/. Reports the load average,
since other jobs on the machine change the time.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from gt2gs_blender.app.progress import TerminalProgress
from gt2gs_blender.core.fit.trainer import DEFAULT_POINTS, DEFAULT_SH_DEGREE, FitConfig, fit_llff
from gt2gs_blender.core.train.densify import DensifyConfig

FERN = ROOT.parent / "shared" / "data" / "scenes" / "fern_llff"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--iterations", type=int, default=FitConfig.iterations)
    parser.add_argument("--points", type=int, default=DEFAULT_POINTS)
    parser.add_argument("--sh-degree", type=int, default=DEFAULT_SH_DEGREE)
    parser.add_argument("--grad-threshold", type=float, default=FitConfig().densify.grad_threshold)
    parser.add_argument("--densify-every", type=int, default=FitConfig.densify_every)
    parser.add_argument("--opacity-reset-every", type=int, default=FitConfig.opacity_reset_every)
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    config = FitConfig(
        iterations=args.iterations,
        densify_every=args.densify_every,
        opacity_reset_every=args.opacity_reset_every,
        densify=DensifyConfig(grad_threshold=args.grad_threshold),
    )
    out = ROOT / "bench" / "out"
    load_before = os.getloadavg()
    report = fit_llff(
        FERN,
        out / "fit_fern",
        config=config,
        n_points=args.points,
        sh_degree=args.sh_degree,
        progress=TerminalProgress("fit"),
    )
    result = {
        **dataclasses.asdict(report),
        "load_before": load_before,
        "load_after": os.getloadavg(),
        "args": vars(args),
    }
    (out / "fit_fern.json").write_text(json.dumps(result, indent=1))
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
