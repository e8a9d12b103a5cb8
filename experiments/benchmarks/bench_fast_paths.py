"""What the fast paths buy: time per step with and without them, and the
largest difference of the two trajectories.

    python experiments/benchmarks/bench_fast_paths.py [--out docs/results/bench] [--scenes a,b]

The fast path keeps what the model's static structure makes constant (mass,
tangents, constraint Jacobian, inverted iteration matrices, the diagonals of
a banded linear model: the objects of ``Operators``), computed once per run,
and in models of 100 or more coordinates (the cube) keeps its LU factors
between Newton iterations and steps (a ``Held`` iteration matrix); the generic path (``fast_paths=False``) evaluates and
factors everything at every Newton iteration. Same windows as
``tests/test_performance.py`` (the cube: 20 steps of its impact window). The
cube's two paths converge to different iterates within the Newton tolerance,
so its difference column is of the order of the tolerance, not round-off.
Writes ``fast_paths.csv`` and ``fast_paths.md``.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from nsga_jax import simulate  # noqa: E402
from nsga_jax._process_settings import configure_jax  # noqa: E402
from nsga_jax._tables import write_csv  # noqa: E402
from nsga_jax.scenes import load_scene  # noqa: E402

configure_jax()  # float64 and XLA's CPU flag, as the command line sets them

WINDOWS = {
    "bouncing_ball": {"t_end": 1.0},
    "rigid_pendulum": {"t_end": 1.0},
    "impacting_bar": {"t_end": 1.5},
    "rigid_box": {"t_end": 0.3},
    "flexible_pendulum": {"t_end": 0.05},
    "flexible_cube": {"h": 3e-5, "t_end": 0.0006, "height": 0.0505, "velocity": -2.43},
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=Path("docs/results/bench"))
    parser.add_argument("--scenes", default=",".join(WINDOWS))
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    rows = []
    for name in args.scenes.split(","):
        scene = load_scene(name, WINDOWS[name])
        fast = scene.scheme()
        run_args = (0.0, scene.solver["t_end"], scene.solver["h"], scene.q0, scene.v0)
        schemes = {"fast": fast, "generic": dataclasses.replace(fast, fast_paths=False)}
        runs = {label: [] for label in schemes}
        for _ in range(args.repeats):  # interleaved, so that slow spells of the machine hit both
            for label, scheme in schemes.items():
                runs[label].append(simulate(scene.model, scheme, *run_args))
        sols = {label: (rs[0], 1e6 * min(r.wall_time for r in rs) / rs[0].n_steps) for label, rs in runs.items()}
        a, b = sols["fast"][0], sols["generic"][0]
        diff = max(np.abs(a.q - b.q).max() / (np.abs(b.q).max() + 1e-300),
                   np.abs(a.v - b.v).max() / (np.abs(b.v).max() + 1e-300))
        rows.append({"scene": name, "n_dof": scene.model.n_dof, "h": scene.solver["h"], "steps": a.n_steps,
                     "fast_us_per_step": sols["fast"][1], "generic_us_per_step": sols["generic"][1],
                     "speedup": sols["generic"][1] / sols["fast"][1], "max_relative_difference": diff})
        r = rows[-1]
        print(f"{name}: fast {r['fast_us_per_step']:.1f} us, generic {r['generic_us_per_step']:.1f} us "
              f"({r['speedup']:.2f}x), difference {diff:.1e}", flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    write_csv(args.out / "fast_paths.csv", rows)
    lines = ["| scene | n | h [s] | steps | fast µs/step | generic µs/step | generic / fast | max rel. difference |",
             "|---|---|---|---|---|---|---|---|"]
    lines += [f"| {r['scene']} | {r['n_dof']} | {r['h']:g} | {r['steps']} | {r['fast_us_per_step']:.1f} | "
              f"{r['generic_us_per_step']:.1f} | {r['speedup']:.2f} | {r['max_relative_difference']:.1e} |"
              for r in rows]
    (args.out / "fast_paths.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
