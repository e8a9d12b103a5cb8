"""The rocking block coming to rest on its two frictional corners
(docs/friction.md, *Settling on redundant contacts*): for each step size,
failed steps, Newton iterations of the position correction (mean / max), the
final tilt, the drift of the coordinates over the last 10 s, the largest
energy above the start, and the impacts (landings: θ changes sign) against
the exact solution's (:func:`~nsga_jax._exact.rocking_impact_times`) while
they are resolvable (the interval since the last one at least
``RESOLVABLE`` steps), paired one to one (:func:`~nsga_jax._exact.match_impacts`):
how many are matched, how many of the run's are extra, and the largest
error of the matched times (a landing is seen at the record after it: up to
one step), printed as a Markdown table.

    python experiments/benchmarks/bench_settling.py [--t-end 60] [--h 1e-3 2e-3 4e-3] [--mu 1.0] [--impacts end]
        [--persistent-contacts jumps] [--tilt 0.15 ...]

``--impacts instants`` runs DS with its impacts located inside their steps
(docs/impact-instants.md) instead of the paper's step;
``--persistent-contacts smooth`` carries the closed contacts' forces in the
smooth motion (docs/friction.md, *Persistent contacts in the smooth motion*).
"""

from __future__ import annotations

import argparse

import numpy as np

from nsga_jax._exact import landings, match_impacts, rocking_impact_times
from nsga_jax._process_settings import configure_jax  # noqa: E402
from nsga_jax.scenes import load_scene

configure_jax()  # float64 and XLA's CPU flag, as the command line sets them

RESOLVABLE = 10
"""Steps between two impacts of the exact solution for the second to count
as resolvable."""


def measure(h: float, t_end: float, mu: float, impacts: str = "end", contacts: str = "jumps",
            tilt: float | None = None) -> str:
    overrides = {"h": h, "t_end": t_end, "mu": mu, "impacts": impacts, "persistent_contacts": contacts}
    scene = load_scene("rocking_block", overrides if tilt is None else {**overrides, "tilt": tilt})
    sol = scene.run(throw=False)
    q, ts = np.asarray(sol.q), np.asarray(sol.ts)
    last = ts >= ts[-1] - 10.0
    drift = float(np.abs(q[last] - q[last][0]).max())
    energy = np.asarray(sol.observables["energy"])
    its = sol.stats["iterations"]["position"]
    p = scene.parameters
    exact = rocking_impact_times(p["width"], p["height"], p["gravity"], p["tilt"], 400)
    measured = ts[landings(np.asarray(sol.observables["theta"]))]
    pairs = match_impacts(measured, exact, h, RESOLVABLE)
    return (f"| {h:g} | {float(p['tilt']):g} | {impacts} | {contacts} | {mu:g} | {t_end:g} | "
            f"{sol.stats['failed_steps']} | "
            f"{its['mean']:.4f} / {its['max']} | {float(q[-1, 2]):.1e} | {drift:.1e} | "
            f"{float(energy.max() / energy[0] - 1):.1e} | {len(measured)} (last {measured[-1]:.3f} s) | "
            f"{pairs['resolvable']} (to {pairs['last']:.3f} s) | {pairs['matched']} | {pairs['extra']} | "
            f"{pairs['max_error']:.1e} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--t-end", type=float, default=60.0)
    parser.add_argument("--h", type=float, nargs="+", default=[1e-3, 2e-3, 4e-3])
    parser.add_argument("--mu", type=float, default=1.0)
    parser.add_argument("--tilt", type=float, nargs="+", default=[None], help="[rad] (default: the scene's)")
    parser.add_argument("--impacts", choices=("end", "instants"), default="end")
    parser.add_argument("--persistent-contacts", choices=("jumps", "smooth"), default="jumps")
    args = parser.parse_args()
    print("| h [s] | tilt [rad] | impacts at | persistent contacts in | mu | t_end [s] | failed steps | "
          "position its. mean / max | final tilt [rad] | "
          "drift, last 10 s [m] | energy above start (rel.) | impacts | exact, resolvable | matched | extra | "
          "matched impact times: max error [s] |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for tilt in args.tilt:
        for h in args.h:
            print(measure(h, args.t_end, args.mu, args.impacts, args.persistent_contacts, tilt), flush=True)


if __name__ == "__main__":
    main()
