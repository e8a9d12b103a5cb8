"""float32 against float64 on every built-in scene, with DS.

    python experiments/studies/precision.py [--out DIR] [--only NAME,...]

For each scene (its default config; the cube on a 20 ms window around its
impact, as experiments/paper/paper_cube.py), runs in
float64 and in float32 at the default tolerance tol_r = 1e-5, and in float32 at
tol_r = 1e-6 and 1e-7, all at the scene's step h, and a float64 reference at
h/4. Reports per run: failed steps (eq. 51 not met within the iteration cap),
mean linear solves per step, time per step (compile apart), the eq. 52 error of
the scene's error observables against the float64 run at the same h (what
float32 costs) and against the reference at h/4 (the discretisation error it
sits next to). Writes DIR/precision.csv (rows of scenes not rerun are kept)
and DIR/precision.md.
"""

from __future__ import annotations

import argparse
import csv
import os
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from nsga_jax._metrics import relative_l1_error  # noqa: E402
from nsga_jax._process_settings import configure_jax  # noqa: E402
from nsga_jax.scenes import REGISTRY, load_scene  # noqa: E402

configure_jax()  # float64 and XLA's CPU flag, as the command line sets them

OVERRIDES = {"flexible_cube": {"height": 0.0505, "velocity": -2.43, "t_end": 0.02}}  # the impact window
RUNS = [("float64", 1e-5), ("float32", 1e-5), ("float32", 1e-6), ("float32", 1e-7)]
FIELDS = ("scene", "dtype", "tol_r", "h", "steps", "failed_steps", "solves_mean", "us_per_step",
          "compile_s", "diff_vs_float64", "error_vs_reference")


def worst_error(sol, ref, names, stride: int = 1) -> float:
    """Largest eq. 52 error over the observables ``names`` (``ref`` sampled every ``stride`` steps)."""
    errors = []
    for k in names:
        y, r = np.asarray(sol.observables[k]), np.asarray(ref.observables[k])[::stride]
        if np.abs(r).sum() > 0:
            errors.append(relative_l1_error(y, r))
    return max(errors)


def run_scene(name: str) -> list[dict]:
    base = OVERRIDES.get(name, {})
    names = list(REGISTRY[name].error_observables)
    h = load_scene(name, base).solver["h"]
    reference = load_scene(name, {**base, "h": h / 4}).run(throw=False)
    rows, f64 = [], None
    for dtype, tol_r in RUNS:
        sol = load_scene(name, {**base, "dtype": dtype, "tol_r": tol_r}).run(throw=False)
        st = sol.stats
        ok = st["failed_steps"] == 0
        f64 = sol if f64 is None else f64
        rows.append({
            "scene": name, "dtype": dtype, "tol_r": tol_r, "h": h, "steps": st["n_steps"],
            "failed_steps": st["failed_steps"], "solves_mean": st["iterations"]["linear_solves"]["mean"],
            "us_per_step": st["us_per_step"], "compile_s": st["compile_time_s"],
            "diff_vs_float64": worst_error(sol, f64, names) if ok else np.nan,
            "error_vs_reference": worst_error(sol, reference, names, stride=4) if ok else np.nan,
        })
        print(" | ".join(f"{k}={v:.3g}" if isinstance(v, float) else f"{k}={v}" for k, v in rows[-1].items()),
              flush=True)
    return rows


def table(rows) -> str:
    lines = ["| scene | dtype | tol_r | failed steps | solves/step | us/step | compile [s] | "
             "float32 − float64 (eq. 52) | error vs h/4 (eq. 52) |", "|" + "---|" * 9]
    for r in rows:
        diff = float(r["diff_vs_float64"])
        diff_text = "—" if r["dtype"] == "float64" else ("failed" if np.isnan(diff) else f"{diff:.1e}")
        err = float(r["error_vs_reference"])
        lines.append(f"| {r['scene']} | {r['dtype']} | {float(r['tol_r']):g} | {r['failed_steps']} | "
                     f"{float(r['solves_mean']):.2f} | {float(r['us_per_step']):.0f} | {float(r['compile_s']):.1f} | "
                     f"{diff_text} | {'—' if np.isnan(err) else f'{err:.1e}'} |")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("docs/results/precision"))
    ap.add_argument("--only", help="comma-separated scenes (default: all)")
    args = ap.parse_args()
    names = args.only.split(",") if args.only else sorted(REGISTRY)
    rows = [r for name in names for r in run_scene(name)]
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / "precision.csv"
    if path.exists():
        with open(path) as fh:
            kept = [r for r in csv.DictReader(fh) if r["scene"] not in names]
        rows = sorted(kept + rows, key=lambda r: r["scene"])
    with open(path, "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=FIELDS)
        writer.writeheader()
        writer.writerows(rows)
    (args.out / "precision.md").write_text(table(rows) + "\n")
    print(table(rows))


if __name__ == "__main__":
    main()
