"""Impacts at their instants against the paper's step: work and precision.

    python experiments/studies/impact_instants.py [--quick]

For each case and step size, one run with the paper's DS and one with
``DS(impact_instants=True)``, interleaved; the error against the exact
solution and the run time (compile apart: ``stats["wall_time_s"]``):

- ``elastic_ball``: e = 1, ρ∞ = 1, 100 s (110 bounces): max |z - z_exact| [m]
  over the run, the last apex and the energy change;
- ``ball``: e = 0.8, 3 s (six bounces): max |vz - vz_exact| [m/s];
- ``slipping_ball``: the planar ball (r = 0.1 m, a solid sphere's inertia)
  dropped from 1 m sliding at vx = 5 m/s, μ = 0.1, e = 0.8: it slips through
  its first impact, after which vx = 5 - μ (1 + e) √(2 g h0) and
  ω = -μ (1 + e) √(2 g h0) r / J m exactly; |vx - vx_exact| at t = 1 s [m/s];
- ``double_pendulum``: 1 s (one wall impact), max error of θ1, θ2, ω1, ω2
  against the event-driven reference [rad, rad/s];
- ``spinning_box``: paper §4.1's box, e = 0.8, 1 s: |e_eff - e| at its
  first impact (one vertex; ``metrics.first_rebound``: the vertex's normal
  rates extrapolated to the instant from either side), and the energy made
  over the run, max E / E(0) - 1;
- ``cradle``: Newton's cradle, five balls 1.03 mm apart, e = 0.9, ball 1
  thrown at 1 m/s, 0.5 s (ten collisions, two of them in one step at
  h = 2 ms): max |x - x_exact| of the centres [m];
- ``rocking_block``: Housner's block (ρ∞ = 0.8), 3 s: the largest error of
  its landing times against the exact ones while they are resolvable
  (10 steps apart at least) [s]; a landing is seen at the record after it;
- ``resting_ball``: e = 0.5, 3 s (its impacts accumulate at 1.355 s):
  run time, and |z|, |v| at the end;
- ``slider_crank``: e = 1 at the stop, ρ∞ = 1 (no numerical damping), 0.1 s:
  the energy change through the impacts (its mean over the 1 ms that starts
  1 ms after the last impulse at the stop: the rod vibrates), and over the run.

Writes docs/results/impact_instants/{impact_instants.md,impact_instants.csv,work_precision.png}.
"""

from __future__ import annotations

import argparse
import csv
import math
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

import nsga_jax as nj  # noqa: E402
from nsga_jax._exact import (  # noqa: E402
    bouncing_ball,
    landings,
    match_impacts,
    newtons_cradle,
    rocking_impact_times,
)
from nsga_jax._metrics import energy_through_impacts, first_rebound  # noqa: E402
from nsga_jax.scenes import load_scene  # noqa: E402

OUT = Path(__file__).resolve().parents[2] / "docs" / "results" / "impact_instants"
G = 9.81
VARIANTS = (("paper DS", {}), ("DS, impacts at instants", {"impact_instants": True}))


def run(scene, T, h, rho_inf, **options):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return nj.simulate(scene.model, nj.DS(rho_inf=rho_inf, **options), 0.0, T, h, scene.q0, scene.v0,
                           throw=False)


def elastic_ball(sol, scene):
    z, _ = bouncing_ball(sol.ts, 1.0, 0.0, G, 1.0)
    energy = 0.5 * sol.v[:, 0] ** 2 + G * sol.q[:, 0]
    return float(np.abs(sol.q[:, 0] - z).max()), {
        "last apex [m]": float(sol.q[sol.ts > sol.ts[-1] - 1.0, 0].max()),
        "energy change": float(energy[-1] / energy[0] - 1.0)}


def ball(sol, scene):
    _, vz = bouncing_ball(sol.ts, 1.0, 0.0, G, 0.8)
    return float(np.abs(sol.v[:, 0] - vz).max()), {}


def slipping_ball(sol, scene):
    m, r = scene.parameters["mass"], scene.parameters["radius"]
    impulse = m * (1.0 + 0.8) * math.sqrt(2.0 * G * 1.0)  # P_N of the first impact [N s]
    vx = 5.0 - 0.1 * impulse / m
    omega = -0.1 * impulse * r / (0.4 * m * r * r)
    obs = scene.observables(sol)
    return float(abs(np.asarray(obs["vx"])[-1] - vx)), {
        "omega error [rad/s]": float(abs(np.asarray(obs["omega"])[-1] - omega))}


def double_pendulum(sol, scene):
    observed, exact = scene.observables(sol), scene.exact(np.asarray(sol.ts))
    return max(float(np.abs(np.asarray(observed[k]) - np.asarray(exact[k])).max())
               for k in scene.spec.error_observables if k in exact), {}


def spinning_box(sol, scene):
    energy = np.asarray(scene.observables(sol)["energy"])
    made = float(energy.max() / energy[0] - 1.0)
    try:
        error = abs(first_rebound(scene.model, sol).restitution - 0.8)
    except ValueError:  # the coarsest steps: the impact's neighbours hold another
        error = math.nan
    return error, {"energy made": made}


def resting_ball(sol, scene):
    return float(max(abs(sol.q[-1, 0]), abs(sol.v[-1, 0]))), {}


def cradle(sol, scene):
    x, _ = newtons_cradle(np.asarray(sol.ts), np.asarray(scene.q0), np.asarray(scene.v0), 0.1, 0.01, 0.9)
    return float(np.abs(np.asarray(sol.q) - x).max()), {}


def rocking_block(sol, scene):
    p = scene.parameters
    exact = rocking_impact_times(p["width"], p["height"], p["gravity"], p["tilt"], 400)
    h = float(sol.ts[1] - sol.ts[0])
    measured = np.asarray(sol.ts)[landings(scene.observables(sol)["theta"])]
    pairs = match_impacts(measured, exact, h)  # resolvable: 10 steps apart at least
    return pairs["max_error"], {"resolvable exact landings": pairs["resolvable"],
                                "matched landings": pairs["matched"], "extra landings": pairs["extra"]}


def slider_crank(sol, scene):
    energy = np.asarray(scene.observables(sol)["energy"])
    change = float(energy[-1] / energy[0] - 1.0) if np.isfinite(energy[-1]) else math.nan
    at_stop = np.asarray(sol.records.impulse)[:, -1] != 0.0
    if not at_stop.any() or not np.isfinite(change):
        return math.nan, {"energy change": change}
    through = energy_through_impacts(sol.ts, energy, at_stop)  # a mean over 1 ms: the rod vibrates
    return abs(through), {"energy change": change, "through impacts": through}


CASES = {  # name: (scene, overrides, t_end [s], ρ∞, step sizes [s], measure, what the error is)
    "elastic_ball": ("bouncing_ball", {"e": 1.0}, 100.0, 1.0, (4e-3, 2e-3, 1e-3, 5e-4, 2.5e-4), elastic_ball,
                     "max abs(z - z_exact) [m]"),
    "ball": ("bouncing_ball", {"e": 0.8}, 3.0, 0.8, (4e-3, 2e-3, 1e-3, 5e-4, 2.5e-4), ball,
             "max abs(vz - vz_exact) [m/s]"),
    "slipping_ball": ("bouncing_ball", {"e": 0.8, "mu": 0.1, "vx": 5.0}, 1.0, 0.8, (4e-3, 2e-3, 1e-3, 5e-4, 2.5e-4),
                      slipping_ball, "abs(vx - vx_exact) at 1 s [m/s]"),
    "double_pendulum": ("double_pendulum", {}, 1.0, 0.8, (4e-3, 2e-3, 1e-3, 5e-4, 2.5e-4), double_pendulum,
                        "max error of θ, ω [rad, rad/s]"),
    "spinning_box": ("rigid_box", {"e": 0.8}, 1.0, 0.8, (1e-2, 5e-3, 2e-3, 1e-3, 5e-4), spinning_box,
                     "abs(e_eff - e) at the first impact"),
    "cradle": ("newtons_cradle", {"e": 0.9, "gap": 1.03e-3}, 0.5, 1.0, (4e-3, 2e-3, 1e-3, 5e-4, 2.5e-4), cradle,
               "max abs(x - x_exact) [m]"),
    "rocking_block": ("rocking_block", {}, 3.0, 0.8, (4e-3, 2e-3, 1e-3, 5e-4), rocking_block,
                      "max error of the landing times [s]"),
    "resting_ball": ("bouncing_ball", {"e": 0.5}, 3.0, 0.8, (1e-3,), resting_ball, "max(abs(z), abs(v)) at 3 s"),
    "slider_crank": ("slider_crank", {"e": 1.0}, 0.1, 1.0, (1e-4, 5e-5, 2.5e-5), slider_crank,
                     "abs(relative energy change through the impacts)"),
}


COLUMNS = ("case", "variant", "h [s]", "error", "error is", "run time [s]", "failed steps", "instants", "fall-backs")


def main() -> int | None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="two step sizes a case, 10 s of the elastic ball")
    parser.add_argument("--out", type=Path, default=OUT)
    parser.add_argument("--plot-only", action="store_true", help="redraw the figure from OUT/impact_instants.csv")
    args = parser.parse_args()
    if args.plot_only:
        with open(args.out / "impact_instants.csv") as f:
            rows = [{k: (float(v) if k in ("h [s]", "error", "run time [s]") else v) for k, v in row.items()}
                    for row in csv.DictReader(f)]
        return plot(rows, args.out / "work_precision.png")
    rows = []
    for name, (scene_name, overrides, t_end, rho_inf, hs, measure, what) in CASES.items():
        scene = load_scene(scene_name, overrides)
        if args.quick:
            hs, t_end = hs[:2], min(t_end, 10.0)
        for h in hs:
            for label, options in VARIANTS:  # interleaved
                sol = run(scene, t_end, h, rho_inf, **options)
                error, extra = measure(sol, scene)
                rows.append({"case": name, "variant": label, "h [s]": h, "error": error, "error is": what,
                             "run time [s]": sol.stats["wall_time_s"], "failed steps": sol.stats["failed_steps"],
                             "instants": sol.stats["impacts_at_instants"],
                             "fall-backs": sol.stats["instant_fallbacks"], **extra})
                print(name, label, f"h={h:g}", f"error={error:.3e}", f"time={sol.stats['wall_time_s']:.3f}s",
                      {k: v for k, v in rows[-1].items() if k not in ("case", "variant", "h [s]", "error")},
                      flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    keys = list(dict.fromkeys(k for row in rows for k in row))
    with open(args.out / "impact_instants.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, keys)
        writer.writeheader()
        writer.writerows(rows)
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    meta = (f"`python experiments/studies/impact_instants.py{' --quick' if args.quick else ''}`, {date.today()}, "
            f"commit {commit}, {platform.machine()} {os.cpu_count()}-core CPU, load average "
            f"{os.getloadavg()[0]:.1f} at the end; run time excludes compilation")
    lines = [meta, "", "| case | variant | h [s] | error | error is | run time [s] | failed | instants | "
             "fall-backs | other |", "|---|---|---|---|---|---|---|---|---|---|"]
    for row in rows:
        other = "; ".join(f"{k} {v:.6g}" for k, v in row.items() if k not in COLUMNS)
        lines.append(f"| {row['case']} | {row['variant']} | {row['h [s]']:g} | {row['error']:.3e} | "
                     f"{row['error is']} | {row['run time [s]']:.3f} | {row['failed steps']} | {row['instants']} | "
                     f"{row['fall-backs']} | {other} |")
    (args.out / "impact_instants.md").write_text("\n".join(lines) + "\n")
    plot(rows, args.out / "work_precision.png")
    print(meta)


def plot(rows, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    cases = ["elastic_ball", "ball", "slipping_ball", "double_pendulum", "spinning_box", "cradle", "rocking_block",
             "slider_crank"]
    fig, axes = plt.subplots(2, 4, figsize=(19.0, 8.0))
    for ax, case in zip(axes.flat, cases):
        for (label, _), marker in zip(VARIANTS, ("o", "s")):
            pts = [r for r in rows if r["case"] == case and r["variant"] == label and r["error"] > 0]  # NaN: unmeasured
            if not pts:
                continue
            ax.loglog([r["run time [s]"] for r in pts], [r["error"] for r in pts], marker=marker, label=label)
            for r in pts:
                ax.annotate(f"{r['h [s]']:g}", (r["run time [s]"], r["error"]), fontsize=7,
                            textcoords="offset points", xytext=(3, 3))
        ax.set_title(case.replace("_", " "), fontsize=10)
        ax.set_xlabel("run time, compile apart [s]")
        ax.set_ylabel(next(r["error is"] for r in rows if r["case"] == case), fontsize=8)
        ax.grid(True, which="both", alpha=0.3)
        # label 2 and 5 of each decade only: all minor labels collide, none leaves a short axis unlabelled
        ax.xaxis.set_minor_formatter(matplotlib.ticker.FuncFormatter(
            lambda x, _: f"{x:g}" if round(x / 10 ** math.floor(math.log10(x))) in (2, 5) else ""))
    axes.flat[0].legend(fontsize=8)
    fig.suptitle("Work-precision: the paper's DS against DS with impacts at their instants\n"
                 "(error against the exact or event-driven solution; point labels: h [s])")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


if __name__ == "__main__":
    sys.exit(main())
