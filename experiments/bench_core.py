"""Per-step cost of the DS stepper on the core scenes, against the cost of the
linear solves a step needs.

    python experiments/bench_core.py [--repeats 5] [--out experiments/out/bench_core]

Prints a table and writes ``bench_core.csv`` and ``bench_core.md``. Times are
the minimum over repeats of complete runs (compile time reported apart, from
the first run). The *floor* is the time of what one bar step cannot avoid: the
three prefactored solves (dense 201 x 201 matrix-vector products with the
precomputed inverses), run in a compiled loop of the same length in the same
process.
"""

from __future__ import annotations

import argparse
import csv
import os
import platform
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from nsga_jax.scenes import load_scene  # noqa: E402

CASES = [
    ("impacting_bar", {"h": 1e-3}),
    ("impacting_bar", {"h": 1e-3, "mass_matrix": "lumped"}),
    ("bouncing_ball", {"h": 1e-3}),
    ("rigid_pendulum", {"h": 1e-3}),
]


def time_scene(name: str, overrides: dict, repeats: int) -> dict:
    scene = load_scene(name, overrides)
    first = scene.run()
    walls = [first.wall_time] + [scene.run().wall_time for _ in range(repeats - 1)]
    wall = min(walls)
    st = first.stats
    return {
        "case": name + ("" if "mass_matrix" not in overrides else f" ({overrides['mass_matrix']} mass)"),
        "h": scene.solver["h"],
        "n_steps": first.n_steps,
        "us_per_step": 1e6 * wall / first.n_steps,
        "compile_s": first.compile_time,
        "linear_solves_mean": st["iterations"]["linear_solves"]["mean"],
    }


def solve_floor(n: int, n_steps: int, solves_per_step: int, repeats: int) -> float:
    """µs per step of ``solves_per_step`` dense (n x n) prefactored solves in a scan."""
    rng = np.random.default_rng(0)
    inverses = jnp.asarray(rng.normal(size=(solves_per_step, n, n)))

    @jax.jit
    def loop(x0):
        def body(x, _):
            for i in range(solves_per_step):
                x = inverses[i] @ x * 0.5
            return x, None

        return jax.lax.scan(body, x0, None, length=n_steps)[0]

    x0 = jnp.ones(n)
    loop(x0).block_until_ready()
    best = np.inf
    for _ in range(repeats):
        t = time.perf_counter()
        loop(x0).block_until_ready()
        best = min(best, time.perf_counter() - t)
    return 1e6 * best / n_steps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--out", type=Path, default=Path("experiments/out/bench_core"))
    args = parser.parse_args()

    rows = [time_scene(name, ov, args.repeats) for name, ov in CASES]
    floor = solve_floor(201, 1500, 3, args.repeats)
    rows.append({"case": "floor: 3 dense 201x201 solves (prefactored)", "h": 1e-3, "n_steps": 1500,
                 "us_per_step": floor, "compile_s": float("nan"), "linear_solves_mean": 3.0})

    device = f"{jax.devices()[0].platform} ({platform.processor() or platform.machine()}, {os.cpu_count()} cores)"
    header = "| case | h [s] | steps | µs/step | compile [s] | linear solves/step |\n|---|---|---|---|---|---|"
    lines = [header] + [
        f"| {r['case']} | {r['h']:g} | {r['n_steps']} | {r['us_per_step']:.1f} | "
        f"{r['compile_s']:.2f} | {r['linear_solves_mean']:.2f} |" for r in rows
    ]
    table = "\n".join(lines)
    print(f"device: {device}, jax {jax.__version__}, float64, min of {args.repeats} runs")
    print(table)
    args.out.mkdir(parents=True, exist_ok=True)
    with open(args.out / "bench_core.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]) + ["device"])
        w.writeheader()
        for r in rows:
            w.writerow({**r, "device": device})
    (args.out / "bench_core.md").write_text(f"device: {device}, jax {jax.__version__}\n\n{table}\n")


if __name__ == "__main__":
    main()
