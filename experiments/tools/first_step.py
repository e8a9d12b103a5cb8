"""The first step of a dense run, estimated and measured, per mesh size and scheme.

Each case runs in its own process: the flexible cube (falling freely from
0.35 m, h = 3e-5 s) by DS on its dense path (``krylov_min_dof=None``) and
by CS, one step in a chunk of one. The measured time is the solution's
``wall_time`` (the constant operators' preparation and the step, the
compilation apart); the estimate is :func:`nsga_jax._first_step.estimate_first_step`
at the LU rate measured in the same process (:func:`nsga_jax._first_step.lu_rate`):

    PYTHONPATH=$PWD python experiments/tools/first_step.py 6 8 10
"""

from __future__ import annotations

import subprocess
import sys

CHILD = """
import sys
import jax
configure_jax()  # float64 and XLA's CPU flag, as the command line sets them
from nsga_jax._process_settings import configure_jax  # noqa: E402
import nsga_jax
from nsga_jax._first_step import estimate_first_step, lu_rate
n, scheme = int(sys.argv[1]), sys.argv[2]
scene = nsga_jax.load_scene("flexible_cube", {"divisions": n, "h": 3e-5, "t_end": 3e-5})
s = nsga_jax.DS(krylov_min_dof=None) if scheme == "ds" else nsga_jax.CS()
est = estimate_first_step(scene.model, s, rate=lu_rate())
sol = nsga_jax.simulate(scene.model, s, 0.0, 3e-5, 3e-5, scene.q0, scene.v0, chunk_size=1, first_step_limit=None)
print(scene.model.n_dof, est.factorisations, f"{est.rate / 1e9:.3g}", f"{est.seconds:.3g}", f"{sol.wall_time:.3g}",
      int(sol.records.newton.iterations[-1].sum()))
"""


def main(sizes: list[int]) -> None:
    print("| divisions | n | scheme | LUs counted | Newton iterations | LU rate [GFLOP/s] | estimate [s] "
          "| measured [s] | measured / estimate |")
    print("|---|---|---|---|---|---|---|---|---|")
    for n in sizes:
        for scheme in ("ds", "cs"):
            out = subprocess.run([sys.executable, "-c", CHILD, str(n), scheme], capture_output=True, text=True)
            if out.returncode:
                raise SystemExit(out.stderr[-2000:])
            dof, lus, rate, est, measured, its = out.stdout.split()
            print(f"| {n} | {int(dof):,} | {scheme.upper()} | {float(lus):g} | {its} | {rate} | {est} | {measured} "
                  f"| {float(measured) / float(est):.2f} |", flush=True)


if __name__ == "__main__":
    main([int(a) for a in sys.argv[1:]] or [6, 8, 10])
