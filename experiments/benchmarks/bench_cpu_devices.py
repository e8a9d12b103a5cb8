"""A batch on one CPU device against the same batch split over N forced host devices.

    python experiments/benchmarks/bench_cpu_devices.py [--scenes a,b] [--batch 64] [--devices 2]
        [--rounds 2] [--timeout 300]

For each scene's ``nsga-jax bench`` case (float64), a batch of identical
members runs in a fresh process with one CPU device and in one with
``--xla_force_host_platform_device_count=N`` (the members split over a
device mesh, as a sweep does), alternately, ``--rounds`` times. Each process
prints the best µs per batch step of three runs (compile apart). A process
that has not finished within ``--timeout`` seconds is reported as hung: on
jaxlib 0.10, large batched LU calls can deadlock several host devices, which
``bounded_lapack_batches`` prevents (docs/sweeps-and-devices.md); the flexible
pendulum hung here before it.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

MEASURE = r"""
import json, sys
from nsga_jax._process_settings import configure_jax
configure_jax()  # float64 and XLA's CPU flag, as the command line sets them
import jax
import numpy as np
from nsga_jax._batch import BatchRun, broadcast_members, member_mesh
from nsga_jax._bench import _bench_scene
from nsga_jax._validation import step_count as _n_steps
name, B = sys.argv[1], int(sys.argv[2])
scene = _bench_scene(name, {"scheme": "ds"}, 2000)
n = _n_steps(0.0, scene.solver["t_end"], scene.solver["h"])
mesh = member_mesh() if len(jax.devices()) > 1 else None
best = np.inf
for _ in range(3):
    run = BatchRun(broadcast_members(scene.model, B), scene.scheme(), 0.0, np.tile(scene.q0, (B, 1)),
                   np.tile(scene.v0, (B, 1)), np.full(B, scene.solver["h"]), np.full(B, n), mesh=mesh)
    for _ in run.chunks():
        pass
    best = min(best, run.wall_time)
print(json.dumps({"devices": len(jax.devices()), "us_per_batch_step": 1e6 * best / n}))
"""

DEFAULT_SCENES = "bouncing_ball,rigid_pendulum,impacting_bar,rigid_box,flexible_pendulum"


def measure(scene: str, batch: int, devices: int, timeout: float) -> float | None:
    """µs per batch step, or None if the process did not finish in time."""
    env = {**os.environ, "NSGA_JAX_CACHE": "off"}
    if devices > 1:
        env["XLA_FLAGS"] = f"{env.get('XLA_FLAGS', '')} --xla_force_host_platform_device_count={devices}".strip()
    try:
        out = subprocess.run([sys.executable, "-W", "ignore", "-c", MEASURE, scene, str(batch)], env=env,
                             capture_output=True, text=True, timeout=timeout, check=True)
    except subprocess.TimeoutExpired:
        return None
    return json.loads(out.stdout.strip().splitlines()[-1])["us_per_batch_step"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", default=DEFAULT_SCENES)
    parser.add_argument("--batch", type=int, default=64)
    parser.add_argument("--devices", type=int, default=2)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--timeout", type=float, default=300.0, help="seconds before a process counts as hung")
    args = parser.parse_args()
    if args.devices < 2 or args.batch % args.devices:
        parser.error("--devices must be >= 2 and divide --batch")
    for scene in args.scenes.split(","):
        results = {1: [], args.devices: []}
        for _ in range(args.rounds):
            for d in results:
                results[d].append(measure(scene, args.batch, d, args.timeout))
        cells = []
        for d, values in results.items():
            shown = ", ".join("hung" if v is None else f"{v:.0f}" for v in values)
            cells.append(f"{d} device(s): {shown}")
        print(f"{scene} batch {args.batch}, us per batch step: " + " | ".join(cells), flush=True)


if __name__ == "__main__":
    main()
