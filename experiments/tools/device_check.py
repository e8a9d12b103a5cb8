"""One short check of an accelerator (GPU) machine: the same results as the CPU, then the benchmark.

    python experiments/tools/device_check.py --out DIR [--max-steps 500] [--repeats 1] [--max-seconds 20]

Run it from the repository root where JAX sees the accelerator (``pip install
-e .`` there, or ``PYTHONPATH=.``). It prints and writes to ``DIR``:

1. ``devices.txt``: JAX's version, backend and devices.
2. ``agreement.csv``: sweeps of the ball (4 restitutions) and the bar (3
   restitutions, 2 step sizes) and a short flexible-pendulum run, on the
   default device and on the CPU in the same process, with the largest
   relative difference of every numeric column (float64: expected at
   round-off, well below the Newton tolerance).
3. ``bench.csv`` and ``bench.md``: ``nsga-jax bench`` (every scene, batches
   1, 64 and 1024, float64 and float32), with fewer steps and repeats than
   the default so that the whole check fits a short lease; its ``device``
   column names the accelerator.
4. ``krylov/<dtype>/krylov.{csv,md,png}``: the large-model benchmark
   (``experiments/benchmarks/bench_krylov.py``): the flexible cube at
   ``--krylov-divisions`` (default 10, 20, 30) on the matrix-free path, and
   on the dense one up to 10 divisions, in float64 and float32 (the GPU
   column of docs/performance.md's "Large models"); ``--krylov-divisions ""``
   skips it.

On a CPU-only machine the "default device" is the CPU and the check compares
it with itself; it is meant for a machine with an accelerator, where it
fills the GPU rows of the benchmark (docs/performance.md).
"""

from __future__ import annotations

import argparse
import csv
import subprocess
import sys
import time
from pathlib import Path

import jax
import numpy as np

import nsga_jax
from nsga_jax._bench import bench, markdown
from nsga_jax._process_settings import configure_jax  # noqa: E402
from nsga_jax._sweep import sweep
from nsga_jax.scenes import load_scene

configure_jax()  # float64 and XLA's CPU flag, as the command line sets them

SWEEPS = {
    "bouncing_ball": ({"e": [0.5, 0.7, 0.8, 0.9]}, None, {"t_end": 1.0}),
    "impacting_bar": ({"e": [0.0, 0.5, 1.0]}, [1e-3, 2e-3], {"t_end": 0.4}),
}
TIMING = {"batch", "batch_wall_s", "member"}


def largest_difference(a: list[dict], b: list[dict]) -> tuple[float, str]:
    """The largest relative difference over the numeric columns of two tables, and its column."""
    worst, where = 0.0, ""
    for ra, rb in zip(a, b, strict=True):
        for key, x in ra.items():
            if key in TIMING or not isinstance(x, (int, float)) or isinstance(x, bool):
                continue
            y = rb[key]
            d = abs(float(x) - float(y)) / max(abs(float(x)), abs(float(y)), 1e-300)
            if abs(float(x) - float(y)) > 1e-14 and d > worst:
                worst, where = d, key
    return worst, where


def agreement(out: Path) -> list[dict]:
    cpu = jax.devices("cpu")[0]
    rows = []
    for name, (grid, hs, overrides) in SWEEPS.items():
        t = time.perf_counter()
        here = sweep(name, grid, hs=hs, overrides=overrides, devices=jax.devices()[:1])
        t_here = time.perf_counter() - t
        with jax.default_device(cpu):
            t = time.perf_counter()
            there = sweep(name, grid, hs=hs, overrides=overrides, devices=[cpu])
            t_cpu = time.perf_counter() - t
        worst, column = largest_difference(here.rows, there.rows)
        rows.append({"case": f"sweep {name}", "runs": len(here.rows), "max_rel_difference": worst,
                     "column": column, "seconds_default_device": t_here, "seconds_cpu": t_cpu})
    scene = load_scene("flexible_pendulum", {"t_end": 0.02})
    t = time.perf_counter()
    a = scene.run()
    t_here = time.perf_counter() - t
    with jax.default_device(cpu):
        t = time.perf_counter()
        b = scene.run()
        t_cpu = time.perf_counter() - t
    scale = np.abs(b.q).max()
    rows.append({"case": "flexible_pendulum q", "runs": 1, "max_rel_difference": float(np.abs(a.q - b.q).max() / scale),
                 "column": "q", "seconds_default_device": t_here, "seconds_cpu": t_cpu})
    with open(out / "agreement.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    return rows


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--max-steps", type=int, default=500)
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--max-seconds", type=float, default=20.0)
    parser.add_argument("--scenes", help="comma-separated scenes for the benchmark (default: all)")
    parser.add_argument("--krylov-divisions", default="10,20,30",
                        help="cube sizes of the large-model benchmark ('' skips it)")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    info = [f"nsga_jax {nsga_jax.__version__}, jax {jax.__version__}, backend {jax.default_backend()}",
            *(f"{d.platform} {d.device_kind} ({d})" for d in jax.devices())]
    (args.out / "devices.txt").write_text("\n".join(info) + "\n")
    print("\n".join(info), flush=True)
    for r in agreement(args.out):
        print(f"{r['case']}: {r['runs']} run(s), largest relative difference from the CPU "
              f"{r['max_rel_difference']:.1e} ({r['column'] or '-'}); {r['seconds_default_device']:.1f} s here, "
              f"{r['seconds_cpu']:.1f} s on the CPU (compile included)", flush=True)
    scenes = None if args.scenes is None else args.scenes.split(",")
    rows = bench(scenes, (1, 64, 1024), ("float64", "float32"), repeats=args.repeats, max_steps=args.max_steps,
                 max_seconds=args.max_seconds, out=args.out)
    table = markdown(rows)
    (args.out / "bench.md").write_text(table + "\n")
    print(table)
    if args.krylov_divisions:
        script = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_krylov.py"
        for dtype in ("float64", "float32"):
            subprocess.run([sys.executable, str(script), "--divisions", args.krylov_divisions, "--dense-max", "10",
                            "--dtype", dtype, "--out", str(args.out / "krylov" / dtype)], check=False)
    return 0


if __name__ == "__main__":
    sys.exit(main())
