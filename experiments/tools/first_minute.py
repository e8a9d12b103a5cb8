"""Where the first minute of a large flexible-cube run goes, per mesh size.

Each size runs in its own process: the scene's default run (DS, h = 3e-5 s,
the cube falling freely from 0.35 m, matrix-free from 500 coordinates) for a
few steps, timed in phases: building the model (the scene's ``make``), the
memory check's estimate, compiling, and the steps themselves (with the
compile apart, as ``Solution.compile_time`` and ``wall_time`` give them).
The sizes run one after another, each in its own process:

    PYTHONPATH=$PWD python experiments/tools/first_minute.py 8 12 16 20
"""

from __future__ import annotations

import subprocess
import sys

CHILD = """
import sys, time
import jax
configure_jax()  # float64 and XLA's CPU flag, as the command line sets them
from nsga_jax._process_settings import configure_jax  # noqa: E402
import nsga_jax
n, steps = int(sys.argv[1]), int(sys.argv[2])
t0 = time.perf_counter()
scene = nsga_jax.load_scene("flexible_cube", {"divisions": n, "h": 3e-5, "t_end": steps * 3e-5})
t1 = time.perf_counter()
sol = scene.run(chunk_size=steps)
t2 = time.perf_counter()
print(scene.model.n_dof, f"{t1 - t0:.2f}", f"{sol.compile_time:.2f}", f"{sol.wall_time / sol.n_steps:.4f}",
      f"{t2 - t1:.2f}", sol.n_steps)
"""


def main(sizes: list[int], steps: int = 8) -> None:
    print("| divisions | n | build [s] | compile [s] | s/step | run() [s] | steps |")
    print("|---|---|---|---|---|---|---|")
    for n in sizes:
        out = subprocess.run([sys.executable, "-c", CHILD, str(n), str(steps)], capture_output=True, text=True)
        if out.returncode:
            raise SystemExit(out.stderr[-2000:])
        dof, build, compile_, step, run, done = out.stdout.split()
        print(f"| {n} | {int(dof):,} | {build} | {compile_} | {step} | {run} | {done} |", flush=True)


if __name__ == "__main__":
    main([int(a) for a in sys.argv[1:]] or [8, 12, 16])
