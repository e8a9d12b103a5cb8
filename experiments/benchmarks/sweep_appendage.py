"""The flexible appendage over a grid of restitutions and hub speeds, with
each way of taking its impacts (docs/impact-instants.md, *A stiff beam's
impacts*): for every run, the failed steps, the time of the first, the
largest energy over the start's, the impacts resolved at their instants and
the Newton iterations of the smooth motion (mean / max), printed and saved as
a Markdown table.

The beam's nodes' rotations are stiff modes the step does not resolve
(ωh ≈ 2,500 at h = 5e-4 s); their accelerations reach 1e6 rad/s² after the
tip's impacts. What this grid checks is that no way of taking the impacts
lets them grow until Newton finds a spurious root.

    python experiments/benchmarks/sweep_appendage.py [--t-end 1.5] [--e 0.2 0.5 0.8] [--omega 1.5 2 3]
        [--out docs/results/bench/appendage_grid.md]

The four variants run in turn at each grid point (interleaved).
"""

from __future__ import annotations

import argparse
import datetime
import platform
import subprocess
import time

import numpy as np

from nsga_jax._process_settings import configure_jax
from nsga_jax.scenes import load_scene

configure_jax()  # float64 and XLA's CPU flag, as the command line sets them

VARIANTS = (("end", "jumps"), ("instants", "jumps"), ("end", "smooth"), ("instants", "smooth"))
"""(impacts, persistent_contacts) of each column: the paper's step, impacts at
their instants, persistent contacts, both."""


def measure(e: float, omega: float, t_end: float, impacts: str, contacts: str) -> dict:
    scene = load_scene("flexible_appendage", {"e": e, "hub_omega": omega, "t_end": t_end, "impacts": impacts,
                                              "persistent_contacts": contacts})
    start = time.perf_counter()
    sol = scene.run(throw=False)
    wall = time.perf_counter() - start
    failed = np.nonzero(np.asarray(sol.records.result))[0]
    energy = np.asarray(sol.observables["energy"])
    its = np.asarray(sol.records.newton.iterations)[:, 0]
    return {"failed": len(failed), "first": float(np.asarray(sol.ts)[failed[0]]) if len(failed) else None,
            "rise": float(np.nanmax(energy) / energy[0] - 1.0) if np.all(np.isfinite(energy)) else float("inf"),
            "instants": int(np.asarray(sol.records.instants).sum()), "its": (float(its.mean()), int(its.max())),
            "wall": wall}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--t-end", type=float, default=1.5)
    parser.add_argument("--e", type=float, nargs="+", default=[0.2, 0.5, 0.8])
    parser.add_argument("--omega", type=float, nargs="+", default=[1.5, 2.0, 3.0])
    parser.add_argument("--out", default=None, help="also write the table to this Markdown file")
    args = parser.parse_args()
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    lines = [f"flexible_appendage, t_end = {args.t_end} s, h = 5e-4 s (scene default); "
             f"{datetime.date.today()}, commit {commit}, {platform.machine()} {platform.system()}", "",
             "| e | ω0 [rad/s] | impacts | persistent contacts | failed steps (first at [s]) "
             "| max E / E0 - 1 | impacts at instants | smooth Newton mean / max "
             "| wall [s] (with compile where a variant first runs) |",
             "|---|---|---|---|---|---|---|---|---|"]
    print("\n".join(lines), flush=True)
    for e in args.e:
        for omega in args.omega:
            for impacts, contacts in VARIANTS:
                r = measure(e, omega, args.t_end, impacts, contacts)
                first = "" if r["first"] is None else f" ({r['first']:.4f})"
                line = (f"| {e} | {omega} | {impacts} | {contacts} | {r['failed']}{first} | {r['rise']:.2e} "
                        f"| {r['instants']} | {r['its'][0]:.2f} / {r['its'][1]} | {r['wall']:.1f} |")
                lines.append(line)
                print(line, flush=True)
    if args.out:
        with open(args.out, "w") as f:
            f.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
