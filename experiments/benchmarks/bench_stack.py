"""A stack of boxes at rest and knocked over (the ``box_stack`` scene): the
targets of a long resting run with friction at every contact.

For each space dimension, N boxes rest for ``--t-rest`` seconds, then the
same stack with its top box pushed at ``--push`` m/s runs ``--t-push``
seconds. Each run reports its failed steps, the largest drift of a box's
centre from its start [m], the Newton iterations per step of the position
correction and of the velocity sub-problem (mean and max), the largest
penetration, the final largest speed [m/s] (the pushed stack: at rest
again?) and the wall time; printed and saved as a Markdown table (``--out``).
Targets: 10 boxes, 10 s at h = 1e-3 s, 0 failed steps, drift < 1e-9 m, in
2D and 3D; pushed, 0 failed steps and at rest at the end.

    python experiments/benchmarks/bench_stack.py [--boxes 10] [--dims 2 3] [--t-rest 10] [--t-push 3]
                                                 [--push 2.0] [--h 1e-3] [--impacts end|instants]
                                                 [--newton-start zero previous] [--cases rest push]
                                                 [--out FILE]
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import time
from datetime import date
from pathlib import Path

from nsga_jax._process_settings import configure_jax  # noqa: E402

configure_jax()  # float64 and XLA's CPU flag, as the command line sets them

HEADER = ("| dim | boxes | case | t_end [s] | failed steps | drift [m] | position its. mean / max | "
          "velocity its. mean / max | max penetration [m] | final speed [m/s] | wall [s] |")


def measure(dim: int, boxes: int, push: float, t_end: float, h: float, impacts: str = "end",
            newton_start: str = "zero") -> dict:
    import numpy as np

    from nsga_jax.scenes import load_scene

    scene = load_scene("box_stack", {"dim": dim, "n_boxes": boxes, "push": push, "t_end": t_end, "h": h,
                                      "impacts": impacts, "newton_start": newton_start})
    start = time.perf_counter()
    sol = scene.run(throw=False)
    wall = time.perf_counter() - start
    its = sol.stats["iterations"]
    obs = sol.observables
    case = "rest" if push == 0 else f"push {push:g} m/s"
    case += ", Newton from the last step's multipliers" if newton_start == "previous" else ""
    if impacts == "instants":
        case += f", {sol.stats['impacts_at_instants']} impacts at instants, {sol.stats['instant_fallbacks']} fall-backs"
    return dict(dim=dim, boxes=boxes, case=case, t_end=t_end,
                failed=sol.stats["failed_steps"], drift=float(np.max(obs["drift"])),
                position=(its["position"]["mean"], its["position"]["max"]),
                velocity=(its["velocity"]["mean"], its["velocity"]["max"]),
                penetration=sol.stats["max_penetration"], speed=float(obs["speed"][-1]), wall=wall)


def row(r: dict) -> str:
    return (f"| {r['dim']} | {r['boxes']} | {r['case']} | {r['t_end']:g} | {r['failed']} | {r['drift']:.2e} | "
            f"{r['position'][0]:.3f} / {r['position'][1]} | {r['velocity'][0]:.3f} / {r['velocity'][1]} | "
            f"{r['penetration']:.1e} | {r['speed']:.1e} | {r['wall']:.0f} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--boxes", type=int, default=10)
    parser.add_argument("--dims", type=int, nargs="+", default=[2, 3])
    parser.add_argument("--t-rest", type=float, default=10.0)
    parser.add_argument("--t-push", type=float, default=3.0)
    parser.add_argument("--push", type=float, default=2.0)
    parser.add_argument("--h", type=float, default=1e-3)
    parser.add_argument("--impacts", choices=("end", "instants"), default="end",
                        help="DS's impacts at the ends of their steps (the paper's) or at their instants")
    parser.add_argument("--newton-start", nargs="+", choices=("zero", "previous"), default=["zero"],
                        help="Newton's start of each step's position correction and velocity jump: zero "
                             "multipliers (the paper's) or the last step's; several are interleaved case by case")
    parser.add_argument("--cases", nargs="+", choices=("rest", "push"), default=["rest", "push"],
                        help="the stack at rest, knocked over, or both (ten 3D boxes at rest: about 0.15 s a step with "
                             "two OpenBLAS threads, tens of iterations and far longer with one: "
                             "docs/friction-scenes.md)")
    parser.add_argument("--out", type=Path, default=Path("experiments/out/bench_stack.md"))
    args = parser.parse_args()
    rows = []
    print(HEADER, flush=True)
    for dim in args.dims:
        cases = {"rest": (0.0, args.t_rest), "push": (args.push, args.t_push)}
        for push, t_end in (cases[case] for case in args.cases):
            for start in args.newton_start:
                rows.append(row(measure(dim, args.boxes, push, t_end, args.h, args.impacts, start)))
                print(rows[-1], flush=True)
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    meta = (f"`python experiments/benchmarks/bench_stack.py --boxes {args.boxes} --dims "
            f"{' '.join(map(str, args.dims))} --t-rest {args.t_rest:g} --t-push {args.t_push:g} --push {args.push:g} "
            f"--h {args.h:g} --impacts {args.impacts} --newton-start {' '.join(args.newton_start)} "
            f"--cases {' '.join(args.cases)}`, "
            f"{date.today()}, commit {commit}, {platform.machine()} "
            f"{os.cpu_count()}-core CPU, "
            f"load average {os.getloadavg()[0]:.1f} at the end")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text("\n".join([meta, "", HEADER, "|" + "---|" * HEADER.count(" | ") + "---|", *rows]) + "\n")
    print(meta)


if __name__ == "__main__":
    main()
