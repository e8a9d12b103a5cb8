"""Cold compile time against time per step, with XLA's CPU backend at its
default optimisation and at ``--xla_backend_optimization_level=0`` (LLVM's
passes off), per built-in scene::

    python experiments/benchmarks/bench_xla_level.py [--scenes box_stack,slider_crank] [--repeats 2] [--out DIR]

Each measurement is a fresh process with no compilation cache (XLA reads its
flags when its backend starts), the two levels interleaved scene by scene and
repeat by repeat; the fastest of the repeats counts. A process compiles the
preparation and the chunk :func:`nsga_jax.simulate` compiles (trace, lower
and XLA together: the seconds before a run's first step), then runs
``--steps`` steps three times and keeps the fastest. Prints and writes
``DIR/xla_level.md``: per scene the two compile times, the two times per
step, the steps after which the default's faster steps repay its longer
compile (``break-even``), and the largest difference between the two runs'
final coordinates (the same operations, without fused multiply-adds at
level 0: round-off apart).
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

LEVEL_0 = "--xla_backend_optimization_level=0"


def measure(scene_name: str, steps: int) -> dict:
    """One scene's compile time and time per step, in this process."""
    import equinox as eqx
    import jax
    import jax.numpy as jnp
    import numpy as np

    import nsga_jax as nj
    from nsga_jax._precision import cast_floats
    from nsga_jax._run_core import prepare_and_init, run_chunk
    from nsga_jax._simulate import chunk_length

    scene = nj.load_scene(scene_name)
    dtype = scene.solver["dtype"]
    model, scheme = cast_floats((scene.model, scene.scheme()), dtype)
    h = jnp.asarray(scene.solver["h"], dtype)
    args0 = (model, scheme, jnp.asarray(0.0, dtype), jnp.asarray(scene.q0, dtype), jnp.asarray(scene.v0, dtype), h)
    length = chunk_length(model)
    steps = min(steps, length)
    t = time.perf_counter()
    prepare = eqx.filter_jit(prepare_and_init).lower(*args0).compile()
    ops, state = prepare(*args0)
    real = jnp.dtype(dtype).type
    chunk_args = (model, scheme, ops, state, h, jnp.asarray(real(0.0)), jnp.asarray(steps, jnp.int32),
                  jnp.asarray(False))
    chunk = eqx.filter_jit(run_chunk).lower(*chunk_args, length).compile()
    compile_s = time.perf_counter() - t
    best = float("inf")
    for _ in range(3):
        t = time.perf_counter()
        end, _ = chunk(*chunk_args, length)
        jax.block_until_ready(end)
        best = min(best, time.perf_counter() - t)
    return {"scene": scene_name, "n_dof": int(model.n_dof), "compile_s": compile_s, "steps": steps,
            "step_us": 1e6 * best / steps, "q": np.asarray(end.q).tolist()}


def child(scene: str, steps: int, level0: bool) -> dict:
    env = dict(os.environ)
    flags = env.get("XLA_FLAGS", "").replace(LEVEL_0, "")
    env["XLA_FLAGS"] = f"{flags} {LEVEL_0}".strip() if level0 else flags.strip()
    out = subprocess.run([sys.executable, __file__, "--one", scene, "--steps", str(steps)], env=env,
                         capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


HEADER = ("| scene | n | compile, default [s] | compile, level 0 [s] | step, default [µs] | step, level 0 [µs] "
          "| break-even [steps] | max abs difference of the final q |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", default="all")
    parser.add_argument("--steps", type=int, default=1000)
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--out", default="experiments/out/xla_level")
    parser.add_argument("--one", help=argparse.SUPPRESS)  # the child process: measure this scene, print JSON
    args = parser.parse_args()
    if args.one:
        from nsga_jax._process_settings import configure_jax

        configure_jax()
        print(json.dumps(measure(args.one, args.steps)))
        return
    import numpy as np

    from nsga_jax.scenes import REGISTRY

    scenes = sorted(REGISTRY) if args.scenes == "all" else args.scenes.split(",")
    rows = [HEADER, "|" + "---|" * HEADER.count(" | ") + "---|"]
    print(HEADER, flush=True)
    for scene in scenes:
        runs: dict[bool, list[dict]] = {False: [], True: []}
        for _ in range(args.repeats):
            for level0 in (False, True):  # interleaved
                runs[level0].append(child(scene, args.steps, level0))
        best = {k: {"compile_s": min(r["compile_s"] for r in v), "step_us": min(r["step_us"] for r in v),
                    "q": np.asarray(v[0]["q"])} for k, v in runs.items()}
        saved = best[False]["compile_s"] - best[True]["compile_s"]
        slower = best[True]["step_us"] - best[False]["step_us"]
        even = f"{saved / slower * 1e6:,.0f}" if slower > 0 and saved > 0 else ("never" if saved <= 0 else "always")
        diff = float(np.max(np.abs(best[False]["q"] - best[True]["q"])))
        default, level0 = best[False], best[True]
        row = (f"| {scene} | {runs[False][0]['n_dof']} | {default['compile_s']:.2f} | {level0['compile_s']:.2f} "
               f"| {default['step_us']:.0f} | {level0['step_us']:.0f} | {even} | {diff:.1e} |")
        rows.append(row)
        print(row, flush=True)
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    meta = (f"`python experiments/benchmarks/bench_xla_level.py --steps {args.steps} --repeats {args.repeats}`, "
            f"{datetime.date.today()}, commit {commit}, {platform.machine()} {os.cpu_count()}-core CPU, "
            f"load average {os.getloadavg()[0]:.1f} at the end; the fastest of {args.repeats} fresh processes each")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "xla_level.md").write_text("\n".join([meta, "", *rows]) + "\n")
    print(meta)


if __name__ == "__main__":
    main()
