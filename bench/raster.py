"""Rasterizer benchmark: every available backend over scene sizes and resolutions, time beside error.

Each configuration runs in its own subprocess so its peak memory (RSS growth over the inputs on the
CPU, torch's peak allocation on CUDA) is its own. With CUDA present the CUDA backends run on the GPU
and the CPU backends on the CPU, in one table. Prints a table and writes a JSON list of records
{backend, device, n, width, height, fwd_ms, fwd_bwd_ms, peak_mib, max_abs_err} (null where not measured).
Error is the max |colour| difference to the float64 dense reference (tests/reference.py) over
pixels where no alpha rule sits on its threshold; it is measured where the reference fits.

    python bench/raster.py --quick            # 10k@256, 50k@512, 200k@512, a few minutes
    python bench/raster.py --json out.json    # the full grid
    python bench/raster.py --quick --interleaved   # the CPU backends alternately in one process: ratios

``--interleaved`` times the CPU backends in this one process, one forward+backward of each in turn per
repeat, and adds each one's median ratio to the first backend's time of the same repeat: on a loaded
machine the ratios hold where the absolute times do not (peak memory is not measured there).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

FULL_N = [10_000, 50_000, 200_000, 1_000_000]
FULL_RES = [256, 512, 1024]
QUICK = [(10_000, 256), (50_000, 512), (200_000, 512)]
REFERENCE_MAX_WORK = 10_000 * 256 * 256  # Gaussians x pixels the float64 reference can afford here
SLOW_BACKEND_LIMIT_S = 30.0  # beyond this fwd+bwd, larger configs of a backend are skipped


def make_scene(n: int, res: int, seed: int = 0):
    """Random SH3 Gaussians filling a 60-degree view at 2-6 units; a few pixels wide at 512 px."""
    import torch

    g = torch.Generator().manual_seed(seed)
    means = torch.randn(n, 3, generator=g) * torch.tensor([0.8, 0.8, 0.7])
    means[:, 2] += 4.0
    quats = torch.randn(n, 4, generator=g)
    scales = torch.exp(torch.randn(n, 3, generator=g) * 0.5 - 4.0)
    opacities = torch.rand(n, generator=g) * 0.9 + 0.05
    sh = torch.randn(n, 16, 3, generator=g) * 0.3
    focal = res / (2 * 0.577)
    viewmats = torch.eye(4)[None]
    ks = torch.tensor([[[focal, 0, res / 2], [0, focal, res / 2], [0, 0, 1.0]]])
    return [means, quats, scales, opacities, sh], viewmats, ks


def rss_mib() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * resource.getpagesize() / 2**20


def clock(device: str) -> float:
    """perf_counter after the device's queued work is done (CUDA runs asynchronously)."""
    import torch

    if device == "cuda":
        torch.cuda.synchronize()
    return time.perf_counter()


def run_one(backend: str, device: str, n: int, res: int, repeats: int) -> dict:
    """Measure one configuration in this process (called in a subprocess)."""
    import torch

    from gt2gs_blender.core.render import rasterization

    params, viewmats, ks = make_scene(n, res)
    params = [p.to(device).requires_grad_(True) for p in params]
    viewmats, ks = viewmats.to(device), ks.to(device)
    warm = rasterization(*params, viewmats, ks, res, res, sh_degree=3, backend=backend)
    assert warm.backend == backend, f"{backend} fell back to {warm.backend}"
    del warm
    base = rss_mib()
    if device == "cuda":
        torch.cuda.reset_peak_memory_stats()
        base = torch.cuda.memory_allocated() / 2**20
    fwd, total = [], []
    for _ in range(repeats):
        for p in params:
            p.grad = None
        t0 = clock(device)
        out = rasterization(*params, viewmats, ks, res, res, sh_degree=3, backend=backend)
        t1 = clock(device)
        (out.colors.sum() + out.depths.sum() * 0.1 + out.alphas.sum()).backward()
        t2 = clock(device)
        fwd.append(t1 - t0)
        total.append(t2 - t0)
    if device == "cuda":
        peak = torch.cuda.max_memory_allocated() / 2**20 - base
    else:
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024 - base
    err = None
    if n * res * res <= REFERENCE_MAX_WORK:
        from tests.reference import render_reference

        ref = render_reference(
            *(p.detach().cpu().numpy() for p in params),
            viewmats[0].cpu().numpy(),
            ks[0].cpu().numpy(),
            res,
            res,
            sh_degree=3,
        )
        diff = (out.colors[0].detach().double().cpu().numpy() - ref.color)[~ref.ambiguous]
        err = float(abs(diff).max())
    return record(
        backend, device, n, res, 1000 * statistics.median(fwd), 1000 * statistics.median(total), max(0.0, peak), err
    )


def measure(backend: str, device: str, n: int, res: int, repeats: int) -> dict:
    """Run one configuration in a fresh subprocess and parse its JSON line."""
    cmd = [sys.executable, __file__, "--one", backend, device, str(n), str(res), "--repeats", str(repeats)]
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT)
    if proc.returncode != 0:
        print(f"  {backend}/{device} n={n} {res}px failed: {proc.stderr.strip().splitlines()[-1:]}", file=sys.stderr)
        return record(backend, device, n, res)
    return json.loads(proc.stdout.strip().splitlines()[-1])


def record(
    backend: str,
    device: str,
    n: int,
    res: int,
    fwd_ms: float | None = None,
    fwd_bwd_ms: float | None = None,
    peak_mib: float | None = None,
    max_abs_err: float | None = None,
) -> dict:
    """One configuration's row of the JSON; without numbers, one that did not run (failed, or skipped as too slow)."""
    return {
        "backend": backend,
        "device": device,
        "n": n,
        "width": res,
        "height": res,
        "fwd_ms": fwd_ms,
        "fwd_bwd_ms": fwd_bwd_ms,
        "peak_mib": peak_mib,
        "max_abs_err": max_abs_err,
    }


def backend_devices() -> list[tuple[str, str]]:
    """(backend, device) pairs to measure: the CUDA backends on the GPU when present, then the CPU's."""
    import torch

    from gt2gs_blender.core.render import available_backends

    devices = (["cuda"] if torch.cuda.is_available() else []) + ["cpu"]
    return [(b, d) for d in devices for b in available_backends(d)]


def interleaved(backends: list[str], configs: list[tuple[int, int]], repeats: int, path: Path) -> int:
    """Time ``backends`` alternately in this process (CPU); print medians and ratios to the first backend."""
    import torch

    from gt2gs_blender.core.render import rasterization

    records = []
    print(f"load {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores, {torch.get_num_threads()} threads")
    print(f"{'backend':9} {'N':>9} {'res':>6} {'fwd ms':>9} {'fwd+bwd ms':>11} {'fwd ratio':>10} {'fwd+bwd ratio':>14}")
    for n, res in configs:
        params, viewmats, ks = make_scene(n, res)
        params = [p.requires_grad_(True) for p in params]
        times: dict[str, list[tuple[float, float]]] = {b: [] for b in backends}
        for repeat in range(repeats + 1):  # the first round warms up (JIT, caches) and is not counted
            for backend in backends:
                for p in params:
                    p.grad = None
                t0 = time.perf_counter()
                out = rasterization(*params, viewmats, ks, res, res, sh_degree=3, backend=backend)
                t1 = time.perf_counter()
                (out.colors.sum() + out.depths.sum() * 0.1 + out.alphas.sum()).backward()
                if repeat:
                    times[backend].append((t1 - t0, time.perf_counter() - t0))
        first = times[backends[0]]
        for backend in backends:
            mine = times[backend]
            rec = {
                "backend": backend,
                "n": n,
                "width": res,
                "fwd_ms": 1000 * statistics.median(t[0] for t in mine),
                "fwd_bwd_ms": 1000 * statistics.median(t[1] for t in mine),
                "fwd_ratio": statistics.median(t[0] / f[0] for t, f in zip(mine, first)),
                "fwd_bwd_ratio": statistics.median(t[1] / f[1] for t, f in zip(mine, first)),
                "load": os.getloadavg()[0],
            }
            records.append(rec)
            print(
                f"{backend:9} {n:>9,} {res:>4}² {rec['fwd_ms']:9.1f} {rec['fwd_bwd_ms']:11.1f} "
                f"{rec['fwd_ratio']:10.2f} {rec['fwd_bwd_ratio']:14.2f}",
                flush=True,
            )
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(records, indent=1))
    print(f"wrote {path}")
    return 0


def fmt(v, spec: str) -> str:
    return "—" if v is None else format(v, spec)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="10k@256, 50k@512 and 200k@512 only")
    parser.add_argument("--json", type=Path, help="default bench/out/raster.json (raster_interleaved.json)")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--backends", default=None, help="comma-separated subset of the available backends")
    parser.add_argument("--interleaved", action="store_true", help="CPU backends alternately in one process")
    parser.add_argument("--one", nargs=4, metavar=("BACKEND", "DEVICE", "N", "RES"), help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.one:
        backend, device, n, res = args.one
        print(json.dumps(run_one(backend, device, int(n), int(res), args.repeats)))
        return 0

    runs = backend_devices()
    if args.backends:
        runs = [(b, d) for b, d in runs if b in args.backends.split(",")]
    configs = QUICK if args.quick else [(n, r) for n in FULL_N for r in FULL_RES]
    if args.interleaved:
        path = args.json or ROOT / "bench" / "out" / "raster_interleaved.json"
        return interleaved([b for b, d in runs if d == "cpu"], configs, args.repeats, path)
    args.json = args.json or ROOT / "bench" / "out" / "raster.json"
    records, too_slow = [], {}
    print(f"{'backend':13} {'N':>9} {'res':>6} {'fwd ms':>9} {'fwd+bwd ms':>11} {'peak MiB':>9} {'max err':>9}")
    for n, res in configs:
        for backend, device in runs:
            key = f"{backend}/{device}"
            if too_slow.get(key, float("inf")) <= n * res * res:
                rec = record(backend, device, n, res)
            else:
                rec = measure(backend, device, n, res, args.repeats)
                if rec["fwd_bwd_ms"] is None or rec["fwd_bwd_ms"] > 1000 * SLOW_BACKEND_LIMIT_S:
                    too_slow[key] = min(too_slow.get(key, float("inf")), n * res * res + 1)
            records.append(rec)
            print(
                f"{key:13} {n:>9,} {res:>4}² {fmt(rec['fwd_ms'], '9.1f')} {fmt(rec['fwd_bwd_ms'], '11.1f')} "
                f"{fmt(rec['peak_mib'], '9.0f')} {fmt(rec['max_abs_err'], '9.1e')}",
                flush=True,
            )
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(records, indent=1))
    print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
