"""Cost of a system against its number of bodies: a chain of N rigid links
(``RigidBody2D``, uniform rods) pinned in series to the ground, released
from the horizontal under gravity, its last link's tip against a wall.

For each N, a first run (JAX's in-memory caches cleared; the Python API
keeps no persistent compilation cache) reports the compile time, then ``--repeats`` runs of
the same program the µs per step (the fastest); printed and saved as a
Markdown table (``--out``).

    python experiments/benchmarks/bench_chain.py [--links 5 20 50] [--steps 400] [--out FILE]
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import time
from datetime import date
from pathlib import Path

import jax

from nsga_jax._process_settings import configure_jax  # noqa: E402

configure_jax()  # float64 and XLA's CPU flag, as the command line sets them


def chain(n_links: int, length: float = 0.2, mass: float = 0.5):
    """``(model, q0, v0)`` of the chain: link i's centre at ((i + 1/2) L, 0)."""
    from nsga_jax.system import Pin, PlaneContact, RigidBody2D, System

    system = System(dim=2, gravity=[0.0, -9.81])
    for i in range(n_links):
        system.add_body(f"link{i}", RigidBody2D(mass, mass * length**2 / 12, [(i + 0.5) * length, 0.0]))
        parent = "ground" if i == 0 else f"link{i - 1}"
        at_parent = [0.0, 0.0] if i == 0 else [length / 2, 0.0]
        system.add_joint(f"pin{i}", Pin(parent, f"link{i}", at_a=at_parent, at_b=[-length / 2, 0.0]))
    reach = n_links * length
    system.add_contact("wall", PlaneContact(f"link{n_links - 1}", normal=[1.0, 0.0], origin=[-0.6 * reach, 0.0],
                                            e=0.5, points=[[length / 2, 0.0]]))
    return system.build()


def measure(n_links: int, steps: int, repeats: int, h: float = 1e-3) -> dict:

    import nsga_jax as nj

    jax.clear_caches()
    model, q0, v0 = chain(n_links)
    start = time.perf_counter()
    first = nj.simulate(model, nj.DS(), 0.0, steps * h, h, q0, v0)
    total = time.perf_counter() - start
    per_step = min(nj.simulate(model, nj.DS(), 0.0, steps * h, h, q0, v0).stats["us_per_step"]
                   for _ in range(repeats))
    return dict(links=n_links, dofs=model.n_dof, constraints=model.n_constraints,
                compile_s=first.stats["compile_time_s"], first_run_s=total, us_per_step=per_step,
                newton=first.stats["iterations"]["position"]["mean"], result=first.stats["result"])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--links", type=int, nargs="+", default=[5, 20, 50])
    parser.add_argument("--steps", type=int, default=400)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", type=Path, default=Path("experiments/out/bench_chain.md"))
    args = parser.parse_args()
    rows = []
    header = "| links | dofs | constraints | compile [s] | µs per step | position Newton its. | result |"
    print(header)
    for n in args.links:
        r = measure(n, args.steps, args.repeats)
        rows.append(f"| {r['links']} | {r['dofs']} | {r['constraints']} | {r['compile_s']:.1f} | "
                    f"{r['us_per_step']:.0f} | {r['newton']:.2f} | {r['result']} |")
        print(rows[-1], flush=True)
    write_table(args.out, f"python experiments/benchmarks/bench_chain.py --links {' '.join(map(str, args.links))} "
                          f"--steps {args.steps}", header, rows)


def write_table(out: Path, command: str, header: str, rows: list[str]) -> None:
    """Save the Markdown table under a line saying how, when, at which commit
    and on what machine it was made; print that line."""
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    meta = (f"`{command}`, {date.today()}, commit {commit}, {platform.machine()} {os.cpu_count()}-core CPU, "
            f"load average {os.getloadavg()[0]:.1f} at the end")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text("\n".join([meta, "", header, "|---" * header.count(" | ") + "|---|", *rows]) + "\n")
    print(meta)


if __name__ == "__main__":
    main()
