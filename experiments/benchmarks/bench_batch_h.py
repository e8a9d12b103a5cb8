"""How to run a sweep over step sizes: separate runs, one padded vmap, or vmap
over groups of similar step counts. Measures all three on the same sweeps.

    python experiments/benchmarks/bench_batch_h.py [--out experiments/out/bench]

Prints and writes ``bench_batch_h.csv``: scene, sweep, mode, wall time of the
runs (compile excluded) and compile time.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


from nsga_jax._process_settings import configure_jax  # noqa: E402
from nsga_jax._studies import MODES, run_step_sizes  # noqa: E402
from nsga_jax._tables import write_csv  # noqa: E402
from nsga_jax.scenes import load_scene  # noqa: E402

configure_jax()  # float64 and XLA's CPU flag, as the command line sets them

SWEEPS = {
    ("bouncing_ball", "narrow"): ({"t_end": 2.0}, [1e-3, 1.25e-3, 1.5e-3, 2e-3]),
    ("bouncing_ball", "wide"): ({"t_end": 2.0}, [1e-4, 3e-4, 1e-3, 3e-3, 1e-2]),
    ("impacting_bar", "narrow"): ({}, [1e-3, 1.25e-3, 1.5e-3, 2e-3]),
    ("impacting_bar", "wide"): ({}, [1e-4, 3e-4, 1e-3, 3e-3, 1e-2]),
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=Path("experiments/out/bench"))
    args = parser.parse_args()
    rows = []
    for (name, sweep), (overrides, hs) in SWEEPS.items():
        scene = load_scene(name, overrides)
        for mode in MODES:
            run_step_sizes(scene, hs, mode=mode)  # compile
            t = time.perf_counter()
            sols = run_step_sizes(scene, hs, mode=mode)
            total = time.perf_counter() - t
            walls = {(s.wall_time, s.compile_time) for s in sols}  # members of a batch share its timings
            rows.append({"scene": name, "sweep": sweep, "h": " ".join(f"{h:g}" for h in hs), "mode": mode,
                         "run_s": sum(w for w, _ in walls), "total_s": total,
                         "steps": int(sum(s.n_steps for s in sols))})
            r = rows[-1]
            print(f"{name:14s} {sweep:6s} {mode:8s} runs {r['run_s']:.3f} s, total with host work {total:.3f} s",
                  flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    write_csv(args.out / "bench_batch_h.csv", rows)


if __name__ == "__main__":
    main()
