"""Three checks of impacts at their instants that have no exact reference.

    python experiments/studies/impact_instants_checks.py

- ``spinning box, global order``: paper §4.1's box (e = 0.8, ρ∞ = 0.8),
  1 s, one impact (on one vertex, at 0.415 s). The largest error of the
  coordinates and velocities at 0.4 s (before the impact) and at 1 s (after
  it) against a run with the option at h = 1e-5 s, and the observed order
  between successive step sizes, for the paper's step and the option.
- ``slider-crank, smooth steps alone``: the run with the option
  (e = 1, ρ∞ = 1, h = 100 µs) is stopped two steps after its last impulse at
  the stop; from that state (the rod ringing, no impact to come) it is run
  on for 4 ms at several step sizes. Its energy change there is the smooth
  steps' error on the rod's vibration, which no impact law touches: the
  mean over [1, 2] ms (as ``metrics.energy_through_impacts`` averages) and
  the largest excursion.
- ``double pendulum, equal error``: the paper's step carried to smaller
  steps than the work-precision study (down to 31.25 µs) next to the option,
  error against the event-driven reference and run time (compile apart, the
  least of three interleaved runs), to read off the run times at equal error.

Writes docs/results/impact_instants/checks.md.
"""

from __future__ import annotations

import os
import platform
import subprocess
import sys
import warnings
from datetime import date
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from nsga_jax._process_settings import configure_jax  # noqa: E402

configure_jax()

from impact_instants import double_pendulum  # noqa: E402  (the script beside this one)

import nsga_jax as nj  # noqa: E402
from nsga_jax.scenes import load_scene  # noqa: E402

OUT = Path(__file__).resolve().parents[2] / "docs" / "results" / "impact_instants" / "checks.md"
BOX_STEPS = (2e-3, 1e-3, 5e-4, 2.5e-4, 1.25e-4)  # [s]
CRANK_STEPS = (1e-4, 5e-5, 2.5e-5, 1e-5, 2.5e-6)  # [s]


def simulate(scene, scheme, t0, t1, h, q0, v0):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return nj.simulate(scene.model, scheme, t0, t1, h, q0, v0)


def state_error(sol, ref, t: float) -> float:
    """max |q - q_ref|, |v - v_ref| at time ``t`` [m, -, m/s, rad/s]."""
    k = int(np.argmin(np.abs(np.asarray(sol.ts) - t)))
    kr = int(np.argmin(np.abs(np.asarray(ref.ts) - t)))
    return float(max(np.abs(np.asarray(sol.q[k]) - np.asarray(ref.q[kr])).max(),
                     np.abs(np.asarray(sol.v[k]) - np.asarray(ref.v[kr])).max()))


def box_order() -> list[str]:
    scene = load_scene("rigid_box", {"e": 0.8})
    ref = simulate(scene, nj.DS(rho_inf=0.8, impact_instants=True), 0.0, 1.0, 1e-5, scene.q0, scene.v0)
    impacts = np.asarray(ref.ts)[np.asarray(ref.records.instants) > 0]
    lines = [f"Spinning box, e = 0.8, ρ∞ = 0.8, 1 s; the reference (the option, h = 1e-5 s) locates "
             f"{len(impacts)} impact(s), at {', '.join(f'{t:.5f}' for t in impacts)} s. Error: max |q - q_ref|, "
             "|v - v_ref| [m, -, m/s, rad/s]; order: log2 of the ratio to the next larger h.", "",
             "| h [s] | paper's step, error at 0.4 s | at 1 s | order at 1 s | option, error at 0.4 s | at 1 s | "
             "order at 1 s |", "|---|---|---|---|---|---|---|"]
    previous: dict[bool, float] = {}
    for h in BOX_STEPS:
        cells = [f"{h:g}"]
        for instants in (False, True):  # interleaved
            sol = simulate(scene, nj.DS(rho_inf=0.8, impact_instants=instants), 0.0, 1.0, h, scene.q0, scene.v0)
            before, after = state_error(sol, ref, 0.4), state_error(sol, ref, 1.0)
            order = np.log2(previous[instants] / after) if instants in previous else np.nan
            previous[instants] = after
            cells += [f"{before:.3e}", f"{after:.3e}", "" if np.isnan(order) else f"{order:.2f}"]
        lines.append("| " + " | ".join(cells) + " |")
        print(lines[-1], flush=True)
    return lines


def crank_smooth_steps() -> list[str]:
    scene = load_scene("slider_crank", {"e": 1.0})
    scheme = nj.DS(rho_inf=1.0, impact_instants=True)
    sol = simulate(scene, scheme, 0.0, 0.1, 1e-4, scene.q0, scene.v0)
    energy = np.asarray(scene.observables(sol)["energy"])
    at_stop = np.nonzero(np.asarray(sol.records.impulse)[:, -1] != 0.0)[0]
    start = at_stop[-1] + 2
    t0 = float(sol.ts[start])
    lines = [f"Slider-crank, e = 1, ρ∞ = 1, the option at h = 100 µs: impulses at the stop in rows "
             f"{', '.join(map(str, at_stop))}; energy two steps after the last, at t0 = {t0:.4f} s: "
             f"{energy[start] / energy[0] - 1:+.3e} of its start. Run on from there for 4 ms (no impact comes); "
             "energy change relative to t0:", "",
             "| h [s] | mean over [1, 2] ms | mean over [3, 4] ms | max abs | impulses at the stop |",
             "|---|---|---|---|---|"]
    for h in CRANK_STEPS:
        on = simulate(scene, scheme, t0, t0 + 4e-3, h, sol.q[start], sol.v[start])
        e, ts = np.asarray(scene.observables(on)["energy"]), np.asarray(on.ts)
        rel = e / e[0] - 1.0

        def mean(a, b):
            return rel[(ts > t0 + a) & (ts <= t0 + b)].mean()

        hits = int((np.asarray(on.records.impulse)[:, -1] != 0.0).sum())
        lines.append(f"| {h:g} | {mean(1e-3, 2e-3):+.3e} | {mean(3e-3, 4e-3):+.3e} | {np.abs(rel).max():.3e} | "
                     f"{hits} |")
        print(lines[-1], flush=True)
    return lines


def pendulum_equal_error() -> list[str]:
    scene = load_scene("double_pendulum", {})
    exact_steps = {False: (2e-3, 1e-3, 5e-4, 2.5e-4, 1.25e-4, 6.25e-5, 3.125e-5), True: (2e-3, 1e-3, 5e-4, 2.5e-4)}
    lines = ["Double pendulum, one wall impact, ρ∞ = 0.8, 1 s: max error of θ1, θ2, ω1, ω2 against the event-driven "
             "reference [rad, rad/s], run time the least of three interleaved runs [s].", "",
             "| h [s] | paper's step, error | run time | option, error | run time |", "|---|---|---|---|---|"]
    for h in exact_steps[False]:
        cells = [f"{h:g}"]
        for instants in (False, True):
            if h not in exact_steps[instants]:
                cells += ["", ""]
                continue
            times = []
            for _ in range(3):
                sol = simulate(scene, nj.DS(rho_inf=0.8, impact_instants=instants), 0.0, 1.0, h, scene.q0, scene.v0)
                times.append(sol.stats["wall_time_s"])
            error = double_pendulum(sol, scene)[0]  # the work-precision study's measure
            cells += [f"{error:.3e}", f"{min(times):.4f}"]
        lines.append("| " + " | ".join(cells) + " |")
        print(lines[-1], flush=True)
    return lines


def main() -> int:
    box, crank, pendulum = box_order(), crank_smooth_steps(), pendulum_equal_error()
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    meta = (f"`python experiments/studies/impact_instants_checks.py`, {date.today()}, commit {commit}, "
            f"{platform.machine()} {os.cpu_count()}-core CPU, load average {os.getloadavg()[0]:.1f} at the end")
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text("\n".join([meta, "", *box, "", *crank, "", *pendulum]) + "\n")
    print(meta)
    return 0


if __name__ == "__main__":
    sys.exit(main())
