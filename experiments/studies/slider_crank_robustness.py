"""Robustness of DS against CS on the slider-crank with a flexible rod and a
stop (scene ``slider_crank``, its default setup), over a range of large steps.

    python experiments/studies/slider_crank_robustness.py [--out DIR] [--hs 1e-5,...] [--ref-h 3e-6]

Each scheme runs at every step size without stopping at failures
(``throw=False``); per run the table gives the outcome (converged, or the
first failure's code and time), the largest bilateral violation at position
[m] and velocity [m/s] level over the steps before the first failure, the
largest penetration of the stop [m], the eq. 52 error of the slider's
position and velocity and of the rod's midpoint deflection against a DS run
at ``--ref-h``, and the mean and largest number of linear solves per step
(CS: three per global iteration, capped at 200 global iterations as in the
paper studies). Writes DIR/robustness.csv, DIR/robustness.md and
DIR/robustness.png (copied to docs/figures/slider_crank_robustness.png).
"""

from __future__ import annotations

import argparse
import math
import shutil
import time
from pathlib import Path

import numpy as np

from nsga_jax import _plotting as plotting
from nsga_jax._metrics import relative_l1_error
from nsga_jax._process_settings import configure_jax  # noqa: E402
from nsga_jax._studies import make_reference, run_step_sizes
from nsga_jax._tables import write_csv
from nsga_jax.scenes import load_scene

configure_jax()  # float64 and XLA's CPU flag, as the command line sets them

SCENE = "slider_crank"
SCHEMES = ("ds", "cs")
CS_MAX_ITER = 200
OBSERVABLES = ("slider_x", "slider_v", "rod_deflection")
FIGURE = Path("docs/figures/slider_crank_robustness.png")


def run(hs, ref_h: float) -> tuple[list[dict], str]:
    t = time.perf_counter()
    reference = make_reference(SCENE, {"scheme": "ds"}, ref_h)
    print(f"reference {reference.description}: {time.perf_counter() - t:.1f} s", flush=True)
    rows = []
    for scheme in SCHEMES:
        extra = {"max_iter": CS_MAX_ITER} if scheme == "cs" else {}
        scene = load_scene(SCENE, {"scheme": scheme, **extra})
        for h, sol in zip(hs, run_step_sizes(scene, hs, mode="separate")):
            st, failed = sol.stats, sol.failed_steps
            ok = slice(None) if failed.size == 0 else slice(0, int(failed[0]))  # the steps before the first failure
            o = {k: np.asarray(v) for k, v in sol.observables.items()}
            ref = reference.values(sol.ts, OBSERVABLES)
            solves = st["iterations"]["linear_solves"]
            row = {
                "scheme": scheme.upper(), "h": h, "steps": sol.n_steps,
                "outcome": "converged" if failed.size == 0 else st["result"],
                "failed_steps": int(failed.size),
                "first_failure_t": float(sol.ts[failed[0]]) if failed.size else math.nan,
                "bilateral_position": float(np.max(o["constraint"][ok])),
                "bilateral_velocity": float(np.max(o["constraint_rate"][ok])),
                "penetration": float(max(0.0, -np.min(o["gap"][ok]))),
                **{f"error_{k}": relative_l1_error(o[k], ref[k]) if failed.size == 0 else math.nan
                   for k in OBSERVABLES},
                "solves_mean": float(solves["mean"]), "solves_max": int(solves["max"]),
                "wall_s": sol.wall_time, "compile_s": sol.compile_time,
            }
            rows.append(row)
            print(" ".join(f"{k}={v:.3g}" if isinstance(v, float) else f"{k}={v}" for k, v in row.items()),
                  flush=True)
    return rows, reference.description


def table(rows) -> str:
    head = ("| scheme | h [s] | outcome | bilateral violation, position [m] | velocity [m/s] | "
            "penetration [m] | " + " | ".join(f"error {k}" for k in OBSERVABLES) + " | solves/step mean | max |")
    lines = [head, "|" + "---|" * (len(OBSERVABLES) + 8)]
    for r in rows:
        outcome = r["outcome"] if r["outcome"] == "converged" else \
            f"{r['outcome']} at t = {r['first_failure_t']:.4g} s"
        errors = " | ".join("—" if not np.isfinite(r[f"error_{k}"]) else f"{r[f'error_{k}']:.2e}"
                            for k in OBSERVABLES)
        lines.append(f"| {r['scheme']} | {r['h']:g} | {outcome} | {r['bilateral_position']:.1e} | "
                     f"{r['bilateral_velocity']:.1e} | {r['penetration']:.1e} | {errors} | "
                     f"{r['solves_mean']:.2f} | {r['solves_max']} |")
    return "\n".join(lines)


def plot(rows, reference: str, path: Path) -> Path:
    """Three log–log panels against h: eq. 52 error of slider_x, largest
    linear solves per step, largest bilateral violation (position and
    velocity); failed runs are red crosses."""
    schemes = list(dict.fromkeys(r["scheme"] for r in rows))
    hs = sorted({r["h"] for r in rows})
    with plotting.style():
        fig, axes = plotting.figure(1, 3, panel=(3.6, 3.0))
        ax_err, ax_it, ax_bil = axes[0]
        for i, s in enumerate(schemes):
            style = plotting.scheme_style(s.lower(), i)
            mine = sorted((r for r in rows if r["scheme"] == s), key=lambda r: r["h"])
            good = [r for r in mine if r["outcome"] == "converged"]
            bad = [r for r in mine if r["outcome"] != "converged"]
            if good:
                ax_err.loglog([r["h"] for r in good], [r["error_slider_x"] for r in good], label=s, **style)
                ax_bil.loglog([r["h"] for r in good], [max(r["bilateral_position"], 1e-17) for r in good],
                              label=f"{s} position [m]", **style)
                ax_bil.loglog([r["h"] for r in good], [max(r["bilateral_velocity"], 1e-17) for r in good],
                              label=f"{s} velocity [m/s]", **{**style, "linestyle": ":"})
            ax_it.loglog([r["h"] for r in mine], [r["solves_max"] for r in mine], label=s, **style)
            for ax in (ax_err, ax_bil):
                if bad:
                    ax.plot([r["h"] for r in bad], [0.0] * len(bad), "x", color="r", ms=9 - 2 * i, mew=1.6,
                            clip_on=False, transform=ax.get_xaxis_transform(), label=f"{s} failed")
            if bad:
                ax_it.plot([r["h"] for r in bad], [r["solves_max"] for r in bad], "x", color="r", ms=9 - 2 * i,
                           mew=1.6, label=f"{s} failed")
        for ax in axes[0]:
            ax.set_xscale("log")
            plotting.log_ticks(ax, "x", hs)
            ax.set_xlabel("h [s]")
        ax_err.set_ylabel("error of slider_x (eq. 52)")
        ax_err.set_title(f"against {reference}", loc="left", fontsize=8)
        ax_it.set_ylabel("largest linear solves per step")
        ax_bil.set_ylabel("largest bilateral violation [m], [m/s]")
        for ax in axes[0]:
            ax.legend(fontsize=7)
        fig.suptitle(plotting.title(SCENE, schemes, hs, "robustness at large steps (t = 0 ... 0.1 s)"))
    return plotting.save(fig, path)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=Path("experiments/out/slider_crank_robustness"))
    parser.add_argument("--hs", default="3e-5,1e-4,3e-4,1e-3,2e-3,3e-3,5e-3")
    parser.add_argument("--ref-h", type=float, default=3e-6)
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    hs = [float(h) for h in args.hs.split(",")]
    t = time.perf_counter()
    rows, reference = run(hs, args.ref_h)
    write_csv(args.out / "robustness.csv", rows)
    text = table(rows)
    (args.out / "robustness.md").write_text(f"reference: {reference}\n\n{text}\n")
    path = plot(rows, reference, args.out / "robustness.png")
    FIGURE.parent.mkdir(parents=True, exist_ok=True)
    shutil.copy(path, FIGURE)
    print(text)
    print(f"{time.perf_counter() - t:.0f} s in all")


if __name__ == "__main__":
    main()
