"""What locating impacts costs: run time (compilation apart) of each scene
with ``impacts = "instants"`` over the paper's step, the two interleaved,
``--repeats`` times each; the ratio of the medians.

    python experiments/benchmarks/bench_impact_instants.py [--repeats 3]

A step with the option looks ahead along a Taylor path (with the held
contacts' acceleration where a contact is closed: a resting body pays a
small saddle solve every step) and splits the rare steps that hold an
impact (docs/impact-instants.md, *Run time*). Prints a Markdown table.
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import warnings
from datetime import date

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from nsga_jax._process_settings import configure_jax  # noqa: E402
from nsga_jax.scenes import load_scene  # noqa: E402

configure_jax()  # float64 and XLA's CPU flag, as the command line sets them

SCENES = {  # label: (scene, overrides)
    "elastic ball, 100 s, h = 1 ms": ("bouncing_ball", {"e": 1.0, "rho_inf": 1.0, "t_end": 100.0}),
    "ball with e = 0.5 coming to rest, 3 s": ("bouncing_ball", {"e": 0.5, "t_end": 3.0}),
    "spinning box, 1 s, h = 1 ms": ("rigid_box", {"e": 0.8, "t_end": 1.0, "h": 1e-3}),
    "double pendulum, 1 s, h = 0.25 ms": ("double_pendulum", {"t_end": 1.0, "h": 2.5e-4}),
    "rocking block, 3 s, h = 1 ms": ("rocking_block", {"t_end": 3.0, "h": 1e-3}),
    "three boxes stacked, top pushed, 2 s": ("box_stack", {"push": 2.0, "t_end": 2.0}),
}


def wall_time(scene_name: str, overrides: dict, impacts: str) -> float:
    scene = load_scene(scene_name, {**overrides, "impacts": impacts})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return float(scene.run(throw=False).stats["wall_time_s"])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    print(f"`bench_impact_instants.py --repeats {args.repeats}`, {date.today()}, commit {commit}, "
          f"{platform.machine()} {os.cpu_count()}-core CPU; median run time, compilation apart\n")
    print("| scene | paper's step [s] | impacts at instants [s] | ratio |")
    print("|---|---|---|---|")
    for label, (name, overrides) in SCENES.items():
        times: dict[str, list[float]] = {"end": [], "instants": []}
        for _ in range(args.repeats):  # interleaved
            for impacts in times:
                times[impacts].append(wall_time(name, overrides, impacts))
        end, instants = float(np.median(times["end"])), float(np.median(times["instants"]))
        print(f"| {label} | {end:.3f} | {instants:.3f} | {instants / end:.2f}× |", flush=True)


if __name__ == "__main__":
    main()
