"""Stability on stiff and extreme cases: every case of configs/extreme/ plus
step-size sweeps of the ball and the bar, with DS, DSn, CS and MJ.

    python experiments/studies/stability.py [--only NAME,...] [--schemes ds,dsn,cs,mj] [--out DIR]

Each run goes on past failures (throw=False) so that the table shows what
happened: outcome (converged, or the first failure's code, step count and
time), max penetration [m], max bilateral violation (position) [m], energy
drift (largest rise of the total energy above its initial value, relative to
the initial energy or, for a body starting at rest on the floor, to m g L),
mean/max linear solves per step and wall time (compile apart). Rows are
appended to DIR/stability.csv as they finish (a rerun skips the rows already
there); DIR/stability.md holds the table.
"""

from __future__ import annotations

import argparse
import csv
import math
import os
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from nsga_jax._packaged import ROOT as PACKAGE  # noqa: E402
from nsga_jax._process_settings import configure_jax  # noqa: E402
from nsga_jax.scenes import load_scene  # noqa: E402

configure_jax()  # float64 and XLA's CPU flag, as the command line sets them

EXTREME = PACKAGE / "configs" / "extreme"
SCHEMES = ("ds", "dsn", "cs", "mj")
FIELDS = ("case", "scheme", "h", "steps", "outcome", "failed_steps", "first_failure_t", "max_penetration",
          "max_bilateral", "energy_drift", "solves_mean", "solves_max", "wall_s")


def cases() -> dict[str, tuple[str, dict]]:
    """name -> (config or scene, overrides)."""
    out = {p.stem: (str(p), {}) for p in sorted(EXTREME.glob("*.toml"))}
    for h in (1e-6, 1e-5, 1e-4, 1e-3, 1e-2, 1e-1):
        out[f"ball_h_{h:g}"] = ("bouncing_ball", {"h": h, "t_end": 1.0 if h < 1e-5 else 3.0})
    for h in (1e-6, 1e-5, 1e-4, 1e-3, 1e-2, 1e-1):
        out[f"bar_h_{h:g}"] = ("impacting_bar", {"h": h, "t_end": 0.52 if h < 1e-5 else 1.5})
    return out


def energy_drift(sol, scene) -> float:
    energy = sol.observables.get("energy")
    if energy is None:
        return math.nan
    energy = np.asarray(energy)
    scale = abs(energy[0])
    if scale < 1e-12:
        p = scene.parameters
        scale = p.get("mass", 1.0) * 9.81 * max(p.get("length", 1.0), 1.0)
    return float(max(energy.max() - energy[0], 0.0) / scale)


def run_case(source: str, overrides: dict, scheme: str) -> dict:
    scene = load_scene(source, {**overrides, "scheme": scheme})
    t = time.perf_counter()
    sol = scene.run(throw=False, progress=False)
    st = sol.stats
    failed = sol.failed_steps
    solves = st["iterations"]["linear_solves"]
    return {
        "h": scene.solver["h"], "steps": st["n_steps"],
        "outcome": "converged" if not len(failed) else st["result"],
        "failed_steps": st["failed_steps"],
        "first_failure_t": float(sol.ts[int(failed[0])]) if len(failed) else math.nan,
        "max_penetration": st["max_penetration"], "max_bilateral": st["max_bilateral_violation_position"],
        "energy_drift": energy_drift(sol, scene),
        "solves_mean": solves["mean"], "solves_max": solves["max"],
        "wall_s": st["wall_time_s"], "elapsed_s": time.perf_counter() - t,
    }


def table(rows) -> str:
    lines = ["| case | scheme | h [s] | outcome | max penetration [m] | max bilateral [m] | energy drift | "
             "solves/step mean / max | wall [s] |", "|" + "---|" * 9]
    for r in rows:
        outcome = r["outcome"]
        if outcome != "converged":
            outcome += f" ({r['failed_steps']} steps, first at t = {float(r['first_failure_t']):.4g} s)"
        drift = float(r["energy_drift"])
        lines.append(f"| {r['case']} | {r['scheme'].upper()} | {float(r['h']):g} | {outcome} | "
                     f"{float(r['max_penetration']):.1e} | {float(r['max_bilateral']):.1e} | "
                     f"{'—' if math.isnan(drift) else f'{drift:.1e}'} | {float(r['solves_mean']):.2f} / "
                     f"{r['solves_max']} | {float(r['wall_s']):.2f} |")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", help="comma-separated case names (default: all)")
    ap.add_argument("--schemes", default=",".join(SCHEMES))
    ap.add_argument("--out", type=Path, default=Path("docs/results/stability"))
    args = ap.parse_args()
    all_cases = cases()
    names = args.only.split(",") if args.only else list(all_cases)
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / "stability.csv"
    done = []
    if path.exists():
        with open(path) as fh:
            done = list(csv.DictReader(fh))
    seen = {(r["case"], r["scheme"]) for r in done}
    new = not path.exists()
    with open(path, "a", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=FIELDS, extrasaction="ignore")
        if new:
            writer.writeheader()
        for name in names:
            source, overrides = all_cases[name]
            for scheme in args.schemes.split(","):
                if (name, scheme) in seen:
                    continue
                row = {"case": name, "scheme": scheme, **run_case(source, overrides, scheme)}
                writer.writerow(row)
                fh.flush()
                done.append({k: str(v) for k, v in row.items()})
                print(table([row]).splitlines()[-1], f"({row['elapsed_s']:.1f} s with compile)", flush=True)
    order = {n: i for i, n in enumerate(all_cases)}
    done.sort(key=lambda r: (order.get(r["case"], 1e9), SCHEMES.index(r["scheme"])))
    (args.out / "stability.md").write_text(table(done) + "\n")


if __name__ == "__main__":
    main()
