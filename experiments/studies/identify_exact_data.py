"""Identification from data that the fitted model did not make, with discrete
and event-aware gradients: the measurement behind ``identify``'s default adjoint.

    python experiments/studies/identify_exact_data.py

(a) bouncing ball: e and the drop height from heights of the closed-form
    solution (e = 0.8, h0 = 1 m), sampled every 5 ms over 1.5 s;
(b) rigid pendulum: the wall position and e from the bob's x of the
    event-driven reference (wall_x = -0.3 m, e = 0.7), every 5 ms over 2 s;
(c) bouncing ball: e from the scene's own run (e = 0.63, 3 s) with 1 % noise;
(d) bouncing ball: e from a run at h = 1e-4 (e = 0.63), every 10 ms.
All start about 30 % off and run DS at h = 1e-3 with optax L-BFGS; the data
are not the discrete model's, so the fitted values carry the model's O(h)
error (or the noise) too. Writes docs/results/identification/exact_data.{json,md}.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from nsga_jax._adjoint import adjoint_named  # noqa: E402
from nsga_jax._exact import bouncing_ball, rigid_pendulum  # noqa: E402
from nsga_jax._identify import Data, identify, synthetic_data  # noqa: E402
from nsga_jax._process_settings import configure_jax  # noqa: E402

configure_jax()  # float64 and XLA's CPU flag, as the command line sets them

RESULTS = Path("docs/results/identification")
G = 9.81


def cases():
    t = np.arange(0.0, 1.5 + 1e-12, 0.005)
    yield ("ball", "bouncing_ball", Data(t=t, values={"z": bouncing_ball(t, 1.0, 0.0, G, 0.8)[0]}),
           {"e": 0.8, "height": 1.0}, {"e": 0.56, "height": 1.3})
    t = np.arange(0.0, 2.0 + 1e-12, 0.005)
    x = rigid_pendulum(t, length=1.0, gravity=G, angle=1.0, omega=0.0, wall_x=-0.3, e=0.7)[0][0]
    yield "pendulum", "rigid_pendulum", Data(t=t, values={"x": x}), {"wall_x": -0.3, "e": 0.7}, \
        {"wall_x": -0.21, "e": 0.49}
    ball = {"e": 0.63, "height": 1.0}
    yield ("ball, 1 % noise", "bouncing_ball", synthetic_data("bouncing_ball", ball, ["z"], noise=0.01, seed=1),
           {"e": 0.63}, {"e": 0.819})
    yield ("ball, h = 1e-4 run", "bouncing_ball",
           synthetic_data("bouncing_ball", {**ball, "h": 1e-4}, ["z"], every=100), {"e": 0.63}, {"e": 0.819})


def main() -> None:
    results = []
    for name, scene, data, true, initial in cases():
        for adjoint in ("discrete", "event"):
            print(f"{name}: {adjoint} gradients", flush=True)
            r = identify(scene, list(true), data, overrides={"h": 1e-3, "height": 1.0} if scene == "bouncing_ball"
                         and "height" not in true else {"h": 1e-3}, initial=initial, true=true,
                         adjoint=adjoint_named(adjoint), max_steps=60, progress=False)
            s = r.summary()
            results.append({"case": name, "adjoint": adjoint, **{k: s[k] for k in (
                "true", "initial", "recovered", "relative_error", "iterations", "evaluations", "stopped_by",
                "converged", "final_loss", "wall_time_s")}})
            print(json.dumps(results[-1]), flush=True)
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "exact_data.json").write_text(json.dumps(results, indent=2) + "\n")
    lines = ["| case | gradients | parameter | true | start | recovered | relative error | iterations | "
             "evaluations | stopped by | converged | final loss | optimise [s] |", "|" + "---|" * 13]
    for r in results:
        for k in r["true"]:
            lines.append(f"| {r['case']} | {r['adjoint']} | {k} | {r['true'][k]:g} | {r['initial'][k]:g} | "
                         f"{r['recovered'][k]:.5g} | {100 * r['relative_error'][k]:.3f} % | {r['iterations']} | "
                         f"{r['evaluations']} | {r['stopped_by']} | {'yes' if r['converged'] else 'no'} | "
                         f"{r['final_loss']:.3g} | {r['wall_time_s']:.1f} |")
    (RESULTS / "exact_data.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
