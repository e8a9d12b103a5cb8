"""The rocking block coming to rest on its two frictional corners
(docs/friction.md, *Settling on redundant contacts*): for each step size,
failed steps, Newton iterations of the position correction (mean / max), the
final tilt, the drift of the coordinates over the last 10 s, and the largest
energy above the start, printed as a Markdown table.

    python experiments/benchmarks/bench_settling.py [--t-end 60] [--h 1e-3 2e-3 4e-3] [--mu 1.0]
"""

from __future__ import annotations

import argparse

import numpy as np

from nsga_jax.scenes import load_scene


def measure(h: float, t_end: float, mu: float) -> str:
    sol = load_scene("rocking_block", {"h": h, "t_end": t_end, "mu": mu}).run(throw=False)
    q, ts = np.asarray(sol.q), np.asarray(sol.ts)
    last = ts >= ts[-1] - 10.0
    drift = float(np.abs(q[last] - q[last][0]).max())
    energy = np.asarray(sol.observables["energy"])
    its = sol.stats["iterations"]["position"]
    return (f"| {h:g} | {mu:g} | {t_end:g} | {sol.stats['failed_steps']} | {its['mean']:.4f} / {its['max']} | "
            f"{float(q[-1, 2]):.1e} | {drift:.1e} | {float(energy.max() / energy[0] - 1):.1e} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--t-end", type=float, default=60.0)
    parser.add_argument("--h", type=float, nargs="+", default=[1e-3, 2e-3, 4e-3])
    parser.add_argument("--mu", type=float, default=1.0)
    args = parser.parse_args()
    print("| h [s] | mu | t_end [s] | failed steps | position its. mean / max | final tilt [rad] | "
          "drift, last 10 s [m] | energy above start (rel.) |")
    print("|---|---|---|---|---|---|---|---|")
    for h in args.h:
        print(measure(h, args.t_end, args.mu), flush=True)


if __name__ == "__main__":
    main()
