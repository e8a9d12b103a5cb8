"""Peak resident memory of a short flexible-cube run, per mesh size.

Each size runs in its own process (``os.wait4`` gives that child's maximum
resident set size); the table compares it with
:func:`nsga_jax._memory.estimate_run_bytes`. The cube starts just above the floor moving down
(height = side/2 + 1e-4 m, -1 m/s) so that every sub-problem (smooth motion,
position correction, velocity jump) runs within the few steps measured;
h = 1e-4 s. Run ONE size at a time on a shared machine:

    PYTHONPATH=$PWD python experiments/tools/memory_peak.py 3 5 7 9 11
"""

from __future__ import annotations

import os
import subprocess
import sys

CHILD = """
import sys
import jax
configure_jax()  # float64 and XLA's CPU flag, as the command line sets them
from nsga_jax._process_settings import configure_jax  # noqa: E402
import nsga_jax
n = int(sys.argv[1])
scene = nsga_jax.load_scene("flexible_cube", {"divisions": n, "height": 0.0501, "velocity": -1.0,
                                              "h": 1e-4, "t_end": 2e-3})
sol = scene.run()
print(scene.model.n_dof, scene.model.n_constraints, sol.n_steps, int(sol.failed_steps.size))
"""


def peak(divisions: int) -> tuple[str, int]:
    """(the child's output line, its maximum resident set size [bytes])."""
    child = subprocess.Popen([sys.executable, "-c", CHILD, str(divisions)], stdout=subprocess.PIPE, text=True)
    _, status, usage = os.wait4(child.pid, 0)
    out = child.stdout.read().strip() if child.stdout else ""
    if status != 0:
        raise SystemExit(f"divisions={divisions} failed (status {status})")
    return out, usage.ru_maxrss * 1024  # Linux: kilobytes


def machine() -> str:
    """Date, commit, CPU, memory and JAX version, for the table's caption."""
    import datetime
    import platform

    import jax

    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    cpu = next((line.split(":", 1)[1].strip() for line in open("/proc/cpuinfo") if line.startswith("model name")),
               platform.processor())
    total = next(int(line.split()[1]) for line in open("/proc/meminfo") if line.startswith("MemTotal"))
    return (f"{datetime.date.today()}, commit {commit}, {cpu}, {os.cpu_count()} cores, {total / 2**20:.0f} GiB, "
            f"jax {jax.__version__}")


def main(sizes: list[int]) -> None:
    from nsga_jax import DS, load_scene
    from nsga_jax._memory import estimate_run_bytes

    print(machine())
    print()
    print("| divisions | coordinates | constraints | peak RSS [GB] | dense n × n | estimate [GB] | estimate / peak |")
    print("|---|---|---|---|---|---|---|")
    for d in sizes:
        out, rss = peak(d)
        model = load_scene("flexible_cube", {"divisions": d, "height": 0.0501}).model
        est = estimate_run_bytes(model, DS(), itemsize=8)
        print(f"| {d} | {model.n_dof} | {out.split()[1]} | {rss / 1e9:.2f} | {est.dense} | {est.total / 1e9:.2f} "
              f"| {est.total / rss:.2f} |", flush=True)


if __name__ == "__main__":
    main([int(a) for a in sys.argv[1:]] or [3, 5, 7, 9, 11])
