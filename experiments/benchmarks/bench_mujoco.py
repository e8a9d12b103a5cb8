"""nsga_jax next to MuJoCo on the same machine: the chain of N rigid links of
``bench_chain.py`` and a ball bouncing on a floor.

The physics differ, and the table says how:

- **Coordinates and joints.** MuJoCo describes the chain by its N hinge
  angles (minimal coordinates: the joints hold exactly by construction);
  nsga_jax by each link's (x, y, θ), 3N coordinates, and 2N pin constraints
  that its DS step enforces at position and velocity level (index-3
  Lagrange multipliers, paper eqs. 20-29).
- **Contact.** MuJoCo's contact is soft: a constraint force with a time
  constant and a damping ratio (``solref``), which lets bodies penetrate and
  has no restitution coefficient; nsga_jax's is hard (the gap never closes
  below round-off) with Newton's impact law of restitution e.
- **Time stepping.** MuJoCo's default semi-implicit Euler (first order)
  against DS's generalized-α (second order on smooth motion).

Both integrate the same mechanism with the same step, and the script checks
that they move it alike: the chain's tip after ``--steps`` steps, each
against MuJoCo's RK4 with a tenth of the step (no contact is reached in
that time), and the
ball's rebound heights (with MuJoCo's default contact and with its
``solref`` set for a restitution e: the default time constant, 0.02 s, and
the damping ratio of a linear spring-damper that rebounds with e,
``ζ = -ln e / √(π² + ln² e)``).

MuJoCo's RK4 at the same step is timed too (for the chain; its contact
steps are Euler's in practice). For each N the runs alternate, ``--repeats`` times, and the fastest
of each is kept (MuJoCo through ``mj_step(..., nstep)``, so that Python's
loop is not timed; nsga_jax's µs per step from its own statistics, compile
apart). Needs ``pip install mujoco``::

    python experiments/benchmarks/bench_mujoco.py [--links 5 20 50 100] [--steps 400] [--repeats 3] [--out DIR]

prints and writes ``DIR/mujoco.md``.
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import subprocess
import sys
import time
from datetime import date
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from bench_chain import chain  # noqa: E402  (configures JAX: float64, the CPU flag)

LENGTH, MASS, H = 0.2, 0.5, 1e-3


def chain_mjcf(n_links: int) -> str:
    """The chain of :func:`bench_chain.chain` in MuJoCo's x-z plane (gravity
    -z), hinges about y, a point-like sphere at the last link's tip against
    the wall x = -0.6 N L."""
    inertia = MASS * LENGTH**2 / 12
    body = (f'<site name="tip" pos="{LENGTH} 0 0"/><geom type="sphere" size="1e-3" pos="{LENGTH} 0 0" '
            f'contype="1" conaffinity="0" mass="0"/>')
    for i in reversed(range(n_links)):
        pos = "0 0 0" if i == 0 else f"{LENGTH} 0 0"
        body = (f'<body name="link{i}" pos="{pos}"><joint type="hinge" axis="0 1 0"/>'
                f'<inertial pos="{LENGTH / 2} 0 0" mass="{MASS}" diaginertia="1e-9 {inertia} {inertia}"/>'
                f'{body}</body>')
    wall = f'<geom type="plane" size="5 5 0.1" pos="{-0.6 * n_links * LENGTH} 0 0" zaxis="1 0 0" conaffinity="1"/>'
    return (f'<mujoco><option timestep="{H}" gravity="0 0 -9.81" integrator="Euler"/>'
            f'<worldbody>{wall}{body}</worldbody></mujoco>')


def ball_mjcf(solref: str | None) -> str:
    """The ball of the ``bouncing_ball`` scene (1 kg, lowest point 1 m above
    the floor, one vertical coordinate), radius 0.1 m."""
    ref = f' solref="{solref}"' if solref else ""
    return (f'<mujoco><option timestep="{H}" gravity="0 0 -9.81" integrator="Euler"/><worldbody>'
            f'<geom type="plane" size="5 5 0.1"{ref}/>'
            f'<body pos="0 0 1.1"><joint type="slide" axis="0 0 1"/>'
            f'<geom type="sphere" size="0.1" mass="1"{ref}/></body></worldbody></mujoco>')


def mujoco_run(xml: str, steps: int, repeats: int, record: bool = False):
    """(fastest µs per step, the data after ``steps`` steps, heights per step when ``record``)."""
    import mujoco

    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    best = math.inf
    for _ in range(repeats):
        mujoco.mj_resetData(model, data)
        t0 = time.perf_counter()
        mujoco.mj_step(model, data, nstep=steps)
        best = min(best, (time.perf_counter() - t0) / steps * 1e6)
    heights = None
    if record:
        mujoco.mj_resetData(model, data)
        heights = np.empty(steps)
        for k in range(steps):
            mujoco.mj_step(model, data)
            heights[k] = data.qpos[0]
    return best, data, heights


def apexes(z: np.ndarray) -> np.ndarray:
    """The heights [m] of the local maxima of ``z`` after its first minimum."""
    inner = (z[1:-1] > z[:-2]) & (z[1:-1] >= z[2:])
    return z[1:-1][inner]


def compare_chain(links: list[int], steps: int, repeats: int) -> list[str]:
    import nsga_jax as nj

    rows = []
    for n in links:
        model, q0, v0 = chain(n)
        first = nj.simulate(model, nj.DS(), 0.0, steps * H, H, q0, v0)
        ours, theirs, rk4 = math.inf, math.inf, math.inf
        rk4_xml = chain_mjcf(n).replace("Euler", "RK4")
        for _ in range(repeats):  # alternately
            ours = min(ours, nj.simulate(model, nj.DS(), 0.0, steps * H, H, q0, v0).stats["us_per_step"])
            theirs = min(theirs, mujoco_run(chain_mjcf(n), steps, 1)[0])
            rk4 = min(rk4, mujoco_run(rk4_xml, steps, 1)[0])
        _, data, _ = mujoco_run(chain_mjcf(n), steps, 1)
        _, data_rk4, _ = mujoco_run(rk4_xml, steps, 1)
        reference_xml = chain_mjcf(n).replace(f'timestep="{H}"', f'timestep="{H / 10}"').replace("Euler", "RK4")
        _, reference, _ = mujoco_run(reference_xml, 10 * steps, 1)  # MuJoCo's RK4 at h / 10
        x, y, angle = np.asarray(first.q[-1][-3:])
        tip = np.array([x + LENGTH / 2 * math.cos(angle), y + LENGTH / 2 * math.sin(angle)])
        exact = reference.site_xpos[0][[0, 2]]
        ours_error, their_error, rk4_error = (float(np.linalg.norm(p - exact))
                                              for p in (tip, data.site_xpos[0][[0, 2]], data_rk4.site_xpos[0][[0, 2]]))
        rows.append(f"| chain, {n} links | {model.n_dof} + {model.n_bilateral} constraints | {n} | "
                    f"{first.stats['compile_time_s']:.1f} | {ours:.0f} | {theirs:.1f} | {ours / theirs:.0f}× | "
                    f"{rk4:.1f} | tip after {steps * H:g} s, from MuJoCo's RK4 at h / 10: nsga_jax "
                    f"{1e3 * ours_error:.4f} mm, MuJoCo Euler {1e3 * their_error:.3f} mm, "
                    f"RK4 {1e3 * rk4_error:.4f} mm |")
        print(rows[-1], flush=True)
    return rows


def compare_ball(steps: int, repeats: int, e: float = 0.8) -> list[str]:
    import nsga_jax as nj

    scene = nj.load_scene("bouncing_ball", {"e": e, "height": 1.0})
    sol = nj.simulate(scene.model, scene.scheme(), 0.0, steps * H, H, scene.q0, scene.v0)
    ours = min(nj.simulate(scene.model, scene.scheme(), 0.0, steps * H, H, scene.q0, scene.v0).stats["us_per_step"]
               for _ in range(repeats))
    z = np.asarray(sol.q[:, 0])
    zeta = -math.log(e) / math.sqrt(math.pi**2 + math.log(e) ** 2)
    rows = []
    ours_apex = ", ".join(f"{a:.3f}" for a in apexes(z)[:3])
    exact = ", ".join(f"{e ** (2 * k):.3f}" for k in (1, 2, 3))
    for label, solref in (("default contact", None), (f"solref 0.02 {zeta:.4f} (e = {e})", f"0.02 {zeta:.4f}")):
        theirs, _, heights = mujoco_run(ball_mjcf(solref), steps, repeats, record=True)
        lowest = 1.0 + heights  # the slide joint's coordinate is the displacement from the start
        their_apex = ", ".join(f"{a:.3f}" for a in apexes(lowest)[:3])
        rows.append(f"| ball, MuJoCo {label} | 1 | 1 | – | {ours:.1f} | {theirs:.2f} | {ours / theirs:.0f}× | – | "
                    f"apexes {their_apex} m, lowest point {1e3 * float(lowest.min()):.1f} mm (nsga_jax: "
                    f"{ours_apex} m, {1e3 * float(z.min()):.0e} mm; exact: {exact} m) |")
        print(rows[-1], flush=True)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--links", type=int, nargs="+", default=[5, 20, 50, 100])
    parser.add_argument("--steps", type=int, default=400)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", type=Path, default=Path("experiments/out/mujoco"))
    args = parser.parse_args()
    try:
        import mujoco
    except ImportError:
        sys.exit("bench_mujoco.py needs MuJoCo: pip install mujoco")
    header = ("| scene | nsga_jax coordinates | MuJoCo coordinates | nsga_jax compile [s] | nsga_jax µs/step "
              "| MuJoCo µs/step (Euler) | ratio | MuJoCo µs/step (RK4) | the motions compared |")
    print(header)
    rows = compare_chain(args.links, args.steps, args.repeats) + compare_ball(3000, args.repeats)
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    meta = (f"`python experiments/benchmarks/bench_mujoco.py --links {' '.join(map(str, args.links))} --steps "
            f"{args.steps}`, {date.today()}, commit {commit}, MuJoCo {mujoco.__version__} (Euler, h = {H:g} s), "
            f"{platform.machine()} {os.cpu_count()}-core CPU, load average {os.getloadavg()[0]:.1f} at the end; "
            f"the ball over 3 s")
    args.out.mkdir(parents=True, exist_ok=True)
    table = [meta, "", header, "|---|---|---|---|---|---|---|---|---|", *rows]
    (args.out / "mujoco.md").write_text("\n".join(table) + "\n")
    print(meta)


if __name__ == "__main__":
    main()
