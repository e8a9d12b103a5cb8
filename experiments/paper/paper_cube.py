"""Paper §4.4, Figs. 9-10: the flexible cube with DS and CS (and DSn, MJ for error against time).

The paper's window (0, 0.3) s at its reference step (3e-6 s) is 10⁵ steps of a
648-dof nonlinear model, beyond a session on 2 cores; this study uses the
impact window instead: the cube starts 0.5 mm above the floor at the paper's
impact speed sqrt(2 g 0.3) = 2.43 m/s and runs for 20 ms (impact, squash and
the start of the rebound), with the paper's step sizes. The paper's node x1 (a
bottom corner) rests on the floor through that window (e = 0; it lifts off
about 25 ms after the impact), so the errors are measured on the top corner
above it, x8, as well.

``--divisions N`` reruns the study on a finer mesh (the paper's has 5
divisions, 648 coordinates). From 1,000 coordinates DS and DSn take the
matrix-free path (:mod:`nsga_jax._integrators.krylov`); CS and MJ stay dense,
so a finer mesh runs DS and DSn unless ``--schemes`` says otherwise. Its
results and figures are named for the mesh (paper_cube_d<N>,
paper_flexible_cube_<N>_divisions_*.png).

    python experiments/paper/paper_cube.py [--out experiments/out/paper_cube]
    python experiments/paper/paper_cube.py --divisions 10 [--out experiments/out/paper_cube_d10]
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from _paper import finish, run_study  # noqa: E402

from nsga_jax._process_settings import configure_jax  # noqa: E402
from nsga_jax._studies import slopes  # noqa: E402

configure_jax()  # float64 and XLA's CPU flag, as the command line sets them

HS = [1e-5, 3e-5, 1e-4, 3e-4]
WINDOW = {"height": 0.0505, "velocity": -2.43, "t_end": 0.02}
PAPER_DIVISIONS = 5


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--divisions", type=int, default=PAPER_DIVISIONS, help="elements along each side")
    parser.add_argument("--schemes", default=None,
                        help="comma-separated (default ds,cs,dsn,mj; ds,dsn on a finer mesh)")
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    paper_mesh = args.divisions == PAPER_DIVISIONS
    schemes = (args.schemes or ("ds,cs,dsn,mj" if paper_mesh else "ds,dsn")).split(",")
    variant = "" if paper_mesh else f"{args.divisions} divisions"
    out = args.out or Path("experiments/out") / ("paper_cube" if paper_mesh else f"paper_cube_d{args.divisions}")
    out.mkdir(parents=True, exist_ok=True)
    rows, reference, elapsed = run_study("flexible_cube", schemes, HS, 2.5e-6, "ds",
                                         {**WINDOW, "divisions": args.divisions}, out, max_iter_cs=100,
                                         observables=("x8_uz", "x8_vz", "x1_uz"), variant=variant)
    by = {(r.scheme, r.h): r for r in rows}
    order = slopes(rows)
    ds_ok = [h for h in HS if not by[("ds", h)].failed_steps]
    claims = [
        ("DS converges with order about 1 at every h",
         f"DS converged at h = {', '.join(f'{h:g}' for h in ds_ok)}; order of x8_uz "
         f"{order.get(('ds', 'x8_uz'), float('nan')):.2f}, of x8_vz {order.get(('ds', 'x8_vz'), float('nan')):.2f}",
         ds_ok == HS and 0.7 < order.get(("ds", "x8_uz"), 0) < 2.2),
    ]
    if "cs" in schemes:
        cs_ok = [h for h in HS if not by[("cs", h)].failed_steps]
        claims.append(("CS converges only for h <= 3e-5",
                       f"CS converged at h = {', '.join(f'{h:g}' for h in cs_ok) or 'none'}",
                       all(h <= 3e-5 for h in cs_ok) and 1e-5 in cs_ok))
    command = "python experiments/paper/paper_cube.py" + ("" if paper_mesh else f" --divisions {args.divisions}")
    finish("flexible_cube", rows, reference, elapsed, claims, out, command, variant)


if __name__ == "__main__":
    main()
