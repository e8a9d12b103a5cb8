"""The cost of a model's energy over many recorded rows (what a sweep's
observables evaluate, ``vmap``-ped over a batch's members and steps).

For the impacting bar, the flexible pendulum and the flexible cube (one
body each), times over ``--rows`` random states the body's
``kinetic_energy`` (a chain's bar or beam: ``Σ_e ½ v_eᵀ M_e v_e`` element
by element; the cube's: ``½ vᵀ (M v)``) against ``½ vᵀ (M v)`` through the
body's product (gather, element products, scatter-add), and the model's
whole energy; and shows what the two ways of summing a chain's element
terms cost (``jnp.sum`` against
:func:`nsga_jax._compat.dot_sum`); the variants alternate, best of
``--repeat``::

    python experiments/benchmarks/bench_energy.py [--rows 48000] [--repeat 5] [--out DIR]

prints and writes ``DIR/energy.md``.
"""

from __future__ import annotations

import argparse
import datetime
import platform
import subprocess
import time
from pathlib import Path

import numpy as np

import nsga_jax as nj

SCENES = {"impacting_bar": 1.0, "flexible_pendulum": 1.0, "flexible_cube": 1 / 24}  # rows, as a share of --rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=48000)
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--out", default="experiments/out/energy")
    args = parser.parse_args()
    nj.configure_jax()
    import jax
    import jax.numpy as jnp

    from nsga_jax._compat import dot_sum
    from nsga_jax.scenes import load_scene

    def best(fns: dict, *xs) -> dict[str, float]:
        for fn in fns.values():
            jax.block_until_ready(fn(*xs))
        times = {k: np.inf for k in fns}
        for _ in range(args.repeat):
            for k, fn in fns.items():  # interleaved
                t0 = time.perf_counter()
                jax.block_until_ready(fn(*xs))
                times[k] = min(times[k], time.perf_counter() - t0)
        return times

    lines = ["| scene | rows | coordinates | the body's `kinetic_energy` [ms] | ½ vᵀ(Mv), assembled product [ms] "
             "| the model's whole energy [ms] |", "|---|---|---|---|---|---|"]
    for name, share in SCENES.items():
        scene = load_scene(name)
        model, n = scene.model, scene.q0.shape[0]
        rows = max(1, int(args.rows * share))
        rng = np.random.default_rng(0)
        q = jnp.asarray(scene.q0 + 1e-3 * rng.standard_normal((rows, n)))
        v = jnp.asarray(rng.standard_normal((rows, n)))
        body = model.bodies[0]  # each of these scenes is one body
        times = best({"elements": jax.jit(jax.vmap(body.kinetic_energy)),
                      "assembled": jax.jit(jax.vmap(lambda q, v: 0.5 * v @ body.mass_product(q, v))),
                      "energy": jax.jit(jax.vmap(model.energy))}, q, v)
        lines.append(f"| {name} | {rows} | {n} | {1e3 * times['elements']:.1f} | {1e3 * times['assembled']:.1f} "
                     f"| {1e3 * times['energy']:.1f} |")
    x = jnp.asarray(np.random.default_rng(1).standard_normal((args.rows, 201)))
    sums = best({"jnp.sum": jax.jit(jax.vmap(lambda u: jnp.sum((u[1:] - u[:-1]) ** 2))),
                 "dot_sum": jax.jit(jax.vmap(lambda u: dot_sum((u[1:] - u[:-1]) ** 2)))}, x)
    lines += ["", "| Σ (u[i+1] - u[i])² over 201 nodes, vmapped | ms |", "|---|---|"]
    lines += [f"| `{k}` | {1e3 * t:.1f} |" for k, t in sums.items()]
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    header = (f"`python experiments/benchmarks/bench_energy.py --rows {args.rows}`, {datetime.date.today()}, "
              f"commit {commit}, {platform.machine()} {platform.processor() or ''}, best of {args.repeat}, "
              "variants interleaved.\n")
    text = header + "\n" + "\n".join(lines) + "\n"
    print(text)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "energy.md").write_text(text)


if __name__ == "__main__":
    main()
