"""Per-step time and peak memory of the flexible cube against its size, for
the dense path (assembled iteration matrices, LU factors held between steps)
and the matrix-free one (element blocks, conjugate gradients:
``DS(krylov_min_dof=0)``); ``--scheme mj`` (``cs``) measures Moreau–Jean's
(CS's) paths with the same tolerances into ``krylov_mj.*`` (``krylov_cs.*``).

Each (divisions, path) runs in its own process, so that ``os.wait4`` gives
its peak resident memory; the paths alternate within each size. The cube
starts 1e-4 m above the floor moving down at 1 m/s with h = 1e-4 s, so every
sub-problem runs within the 20 steps measured (the whole bottom face lands in
step 2). The time per step is the run's execution time over its steps
(compilation apart); the table also gives the largest |Δq| between the paths
where both ran, in units of tol_r |q|max. Writes ``krylov.csv``,
``krylov.md`` and ``krylov.png`` (log-log, with the fitted exponent of each
path) to ``--out``. Run it alone on the machine:

    PYTHONPATH=$PWD python experiments/benchmarks/bench_krylov.py --divisions 3,5,7,10,15,20 \\
        --paths dense,krylov --dense-max 11 --out docs/results/bench
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

CHILD = r"""
import dataclasses, json, sys
import jax
jax.config.update("jax_enable_x64", sys.argv[4] == "float64")
import numpy as np
import nsga_jax
from nsga_jax._memory import estimate_run_bytes
d, path, out = int(sys.argv[1]), sys.argv[2], sys.argv[3]
scene = nsga_jax.load_scene("flexible_cube", {"divisions": d, "height": 0.0501, "velocity": -1.0,
                                              "h": 1e-4, "t_end": float(sys.argv[5]) * 1e-4})
base = scene.scheme()
if sys.argv[6] in ("mj", "cs"):
    base = getattr(nsga_jax, sys.argv[6].upper())(tol_r=base.tol_r, tol_f=base.tol_f, max_iter=base.max_iter)
scheme = dataclasses.replace(base, krylov_min_dof=0 if path == "krylov" else None)
est = estimate_run_bytes(scene.model, scheme, 8 if sys.argv[4] == "float64" else 4)
sol = nsga_jax.simulate(scene.model, scheme, 0.0, scene.solver["t_end"], scene.solver["h"], scene.q0, scene.v0,
                        dtype=sys.argv[4])
it = np.asarray(sol.iterations)
np.save(out, np.asarray(sol.q[-1]))
print(json.dumps({"n_dof": scene.model.n_dof, "n_contacts": scene.model.n_constraints, "steps": int(sol.n_steps),
                  "failed": int(np.size(sol.failed_steps)), "compile_s": sol.compile_time,
                  "s_per_step": sol.wall_time / sol.n_steps, "newton_mean": it.mean(0).round(2).tolist(),
                  "newton_max": it.max(0).tolist(), "est_GB": est.total / 1e9,
                  "q_max": float(np.abs(np.asarray(sol.q)).max()), "tol_r": float(scheme.tol_r)}))
"""

FIELDS = ["divisions", "n_dof", "n_contacts", "path", "dtype", "steps", "failed", "compile_s", "s_per_step",
          "us_per_step_per_dof", "newton_mean", "newton_max", "est_GB", "peak_GB", "dq_over_tol"]


def run(divisions: int, path: str, dtype: str, steps: int, tmp: Path, scheme: str = "ds") -> dict:
    out = tmp / f"q_{divisions}_{path}_{dtype}.npy"
    child = subprocess.Popen([sys.executable, "-c", CHILD, str(divisions), path, str(out), dtype, str(steps), scheme],
                             stdout=subprocess.PIPE, text=True, env={**os.environ, "NSGA_JAX_SKIP_MEMORY_CHECK": "1"})
    _, status, usage = os.wait4(child.pid, 0)
    text = child.stdout.read() if child.stdout else ""
    if status != 0:
        raise SystemExit(f"divisions={divisions} path={path} failed (status {status})")
    row = json.loads(text.strip().splitlines()[-1])
    row.update(divisions=divisions, path=path, dtype=dtype, peak_GB=usage.ru_maxrss * 1024 / 1e9,
               us_per_step_per_dof=1e6 * row["s_per_step"] / row["n_dof"], q_file=str(out))
    return row


def fit(rows: list[dict], path: str, min_dof: int) -> float | None:
    """The exponent p of s_per_step ∝ n_dof^p over the sizes from ``min_dof``."""
    import numpy as np

    pts = [(r["n_dof"], r["s_per_step"]) for r in rows if r["path"] == path and r["n_dof"] >= min_dof]
    if len(pts) < 2:
        return None
    x, y = np.log([p[0] for p in pts]), np.log([p[1] for p in pts])
    return float(np.polyfit(x, y, 1)[0])


def plot(rows: list[dict], fits: dict, path: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, bx) = plt.subplots(1, 2, figsize=(10, 4))
    for name, marker in (("dense", "s"), ("krylov", "o")):
        pts = sorted((r["n_dof"], r["s_per_step"], r["peak_GB"]) for r in rows if r["path"] == name)
        if not pts:
            continue
        label = f"{'matrix-free (CG)' if name == 'krylov' else 'dense (LU)'}"
        if fits.get(name) is not None:
            label += f", time ∝ n^{fits[name]:.2f}"
        ax.loglog([p[0] for p in pts], [p[1] for p in pts], marker=marker, label=label)
        bx.loglog([p[0] for p in pts], [p[2] for p in pts], marker=marker, label=label.split(",")[0])
    ax.set_xlabel("coordinates n [-]")
    ax.set_ylabel("time per step [s]")
    ax.set_title("time per step")
    bx.set_xlabel("coordinates n [-]")
    bx.set_ylabel("peak resident memory [GB]")
    bx.set_title("peak memory of the process")
    from matplotlib.ticker import NullFormatter

    for a in (ax, bx):
        a.grid(True, which="both", alpha=0.3)
        a.xaxis.set_minor_formatter(NullFormatter())  # the decades only: minor labels overlap
        a.legend()
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def title(dtype: str, steps, args) -> str:
    import platform

    scheme = {"mj": "Moreau-Jean", "cs": "CS"}.get(getattr(args, "scheme", "ds"), "DS")
    return (f"Flexible cube landing on a floor, {scheme}, {dtype}, h = 1e-4 s, 20 steps a size\n"
            f"dense LU against matrix-free CG; 2-core {platform.machine()} CPU (bench_krylov.py)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--divisions", default="3,5,7,10")
    parser.add_argument("--paths", default="dense,krylov")
    parser.add_argument("--dense-max", type=int, default=11, help="largest divisions the dense path runs")
    parser.add_argument("--dtype", default="float64")
    parser.add_argument("--steps", type=int, default=20)
    parser.add_argument("--fit-from", type=int, default=1000, help="smallest n in the fitted exponent")
    parser.add_argument("--out", default="docs/results/bench")
    parser.add_argument("--plot-only", action="store_true", help="redraw krylov.png from krylov.csv in --out")
    parser.add_argument("--scheme", choices=("ds", "mj", "cs"), default="ds")
    args = parser.parse_args()
    stem = "krylov" if args.scheme == "ds" else f"krylov_{args.scheme}"
    if args.plot_only:
        with open(Path(args.out) / f"{stem}.csv") as f:
            rows = [{**r, "n_dof": int(r["n_dof"]), "s_per_step": float(r["s_per_step"]),
                     "peak_GB": float(r["peak_GB"])} for r in csv.DictReader(f)]
        fits = {p: fit(rows, p, args.fit_from) for p in ("dense", "krylov")}
        plot(rows, fits, Path(args.out) / f"{stem}.png", title(rows[0]["dtype"], len(rows), args))
        return
    import numpy as np

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tools"))
    from memory_peak import machine

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for d in [int(x) for x in args.divisions.split(",")]:
            done = {}
            for path in args.paths.split(","):
                if path == "dense" and d > args.dense_max:
                    continue
                row = run(d, path, args.dtype, args.steps, Path(tmp), args.scheme)
                done[path] = row
                rows.append(row)
                print(f"d={d:3d} n={row['n_dof']:7,d} {path:6s} {row['s_per_step']:.4f} s/step "
                      f"compile {row['compile_s']:.1f} s peak {row['peak_GB']:.2f} GB est {row['est_GB']:.2f} GB "
                      f"newton max {row['newton_max']} failed {row['failed']}", flush=True)
            if len(done) == 2:
                qa, qb = (np.load(done[p]["q_file"]) for p in ("krylov", "dense"))
                scale = done["dense"]["tol_r"] * done["dense"]["q_max"]
                for r in done.values():
                    r["dq_over_tol"] = float(np.abs(qa - qb).max() / scale)
    fits = {p: fit(rows, p, args.fit_from) for p in ("dense", "krylov")}
    caption = (f"bench_krylov.py --scheme {args.scheme} --divisions {args.divisions} --dtype {args.dtype} "
               f"--steps {args.steps}; "
               f"{machine()}")
    with open(out / f"{stem}.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=FIELDS, extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    lines = [f"Flexible cube, {args.scheme.upper()}, h = 1e-4 s, {args.steps} steps through the landing; {caption}", "",
             "| divisions | n | contacts | path | s/step | µs/step/dof | compile [s] | Newton max (s, p, v) | "
             "peak [GB] | estimate [GB] | max Δq / (tol_r q_max) |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        dq = f"{r['dq_over_tol']:.2g}" if "dq_over_tol" in r else "–"
        lines.append(f"| {r['divisions']} | {r['n_dof']:,} | {r['n_contacts']} | {r['path']} | {r['s_per_step']:.4g} | "
                     f"{r['us_per_step_per_dof']:.3g} | {r['compile_s']:.1f} | {r['newton_max']} | "
                     f"{r['peak_GB']:.2f} | {r['est_GB']:.2f} | {dq} |")
    lines += ["", "Fitted exponent of time per step against n (n >= "
              f"{args.fit_from}): " + ", ".join(f"{p} {v:.2f}" for p, v in fits.items() if v is not None)]
    (out / f"{stem}.md").write_text("\n".join(lines) + "\n")
    plot(rows, fits, out / f"{stem}.png", title(args.dtype, args.steps, args))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
