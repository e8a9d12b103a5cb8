"""Per-step cost of the DS stepper on every built-in scene, split against its parts.

    python experiments/benchmarks/bench_scenes.py [--repeats 3] [--scenes a,b] [--out experiments/out/bench]

For each scene: the time per step of complete runs (minimum over repeats;
compile time apart, from the first run) and, measured in the same process at
the initial state, what a step is made of:

- ``assembly_us``: one evaluation of the force and of the tangents K, C
  (element-level jacfwd, vmap, scatter-add) -- the force only for linear
  models, whose tangents are constant;
- ``factor_solve_us``: one dense LU factorisation and solve of an n x n matrix
  (what each Newton iteration of a nonlinear model pays);
- ``inverse_solve_us``: one product with a precomputed n x n inverse (what a
  linear model pays per solve);
- ``step_us``: one step from the initial state, chained in a ``fori_loop``
  that keeps only the state (no records, no time-loop bookkeeping; the steps
  are those of the run's start, usually free flight).

Writes ``bench_scenes.csv`` and ``bench_scenes.md`` to ``--out``.
"""

from __future__ import annotations

import argparse
import os
import platform
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import nsga_jax  # noqa: E402, F401
from nsga_jax._bench import CASES as BENCH_CASES  # noqa: E402
from nsga_jax._bench import per_call  # noqa: E402
from nsga_jax._process_settings import configure_jax  # noqa: E402
from nsga_jax._tables import write_csv  # noqa: E402
from nsga_jax.scenes import load_scene  # noqa: E402

configure_jax()  # float64 and XLA's CPU flag, as the command line sets them

# the package's benchmark cases, with the cube at the paper's middle step over its impact window
CASES = {**BENCH_CASES, "flexible_cube": {**BENCH_CASES["flexible_cube"], "h": 3e-5}}


def parts(scene, repeats: int) -> dict:
    model = scene.model
    n = model.n_dof
    q, v = jnp.asarray(scene.q0), jnp.asarray(scene.v0)
    t = jnp.zeros(())
    inner = max(3, min(2000, int(2e6 / n**2)))
    tiny = 1e-30
    if model.linear_force:
        def assemble(q):
            return q + tiny * model.force(q, v, t)
    else:
        def assemble(q):
            K, C = model.tangents(q, v, t)
            return q + tiny * (model.force(q, v, t) + K[0] + C[0])
    rng = np.random.default_rng(0)
    A = jnp.asarray(rng.normal(size=(n, n)) + n * np.eye(n))
    A_inv = jnp.linalg.inv(A)
    b = jnp.ones(n)
    scheme = scene.scheme()
    h = scene.solver["h"]
    ops = jax.jit(lambda: scheme.prepare(model, h, 0.0))()
    state = jax.jit(lambda q, v: scheme.init(model, 0.0, q, v))(q, v)
    steps = max(3, min(500, inner))
    return {
        "step_us": 1e6 * per_call(lambda s: scheme.step(model, ops, s, h)[0], state, repeats, steps),
        "assembly_us": 1e6 * per_call(assemble, q, repeats, inner),
        "factor_solve_us": 1e6 * per_call(lambda x: jnp.linalg.solve(A + tiny * x[0], x), b, repeats, inner),
        "inverse_solve_us": 1e6 * per_call(lambda x: A_inv @ x, b, repeats, inner),
    }


def run_case(name: str, overrides: dict, repeats: int) -> dict:
    scene = load_scene(name, overrides)
    first = scene.run()
    walls = [first.wall_time] + [scene.run().wall_time for _ in range(repeats - 1)]
    st = first.stats
    row = {
        "scene": name,
        "n_dof": scene.model.n_dof,
        "h": scene.solver["h"],
        "n_steps": first.n_steps,
        "us_per_step": 1e6 * min(walls) / first.n_steps,
        "compile_s": first.compile_time,
        "solves_per_step": st["iterations"]["linear_solves"]["mean"],
    }
    row.update(parts(scene, repeats))
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--scenes", default=",".join(CASES))
    parser.add_argument("--out", type=Path, default=Path("experiments/out/bench"))
    args = parser.parse_args()

    rows = []
    for name in args.scenes.split(","):
        rows.append(run_case(name, CASES[name], args.repeats))
        r = rows[-1]
        print(f"{name}: {r['us_per_step']:.1f} us/step, compile {r['compile_s']:.2f} s", flush=True)

    device = f"{jax.devices()[0].platform} ({platform.machine()}, {os.cpu_count()} cores)"
    lines = [
        "| scene | n | h [s] | steps | µs/step | compile [s] | solves/step | assembly [µs] "
        "| dense factor+solve [µs] | prefactored solve [µs] | step alone [µs] |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['scene']} | {r['n_dof']} | {r['h']:g} | {r['n_steps']} | {r['us_per_step']:.1f} | "
            f"{r['compile_s']:.1f} | {r['solves_per_step']:.2f} | {r['assembly_us']:.1f} | "
            f"{r['factor_solve_us']:.1f} | {r['inverse_solve_us']:.1f} | {r['step_us']:.1f} |"
        )
    table = "\n".join(lines)
    header = f"device: {device}, jax {jax.__version__}, float64, minimum of {args.repeats} runs"
    print(header)
    print(table)
    args.out.mkdir(parents=True, exist_ok=True)
    write_csv(args.out / "bench_scenes.csv", [{**r, "device": device} for r in rows])
    (args.out / "bench_scenes.md").write_text(header + "\n\n" + table + "\n")


if __name__ == "__main__":
    main()
