"""Where a run's compile time goes, per built-in scene: tracing, lowering to
StableHLO, and XLA's compilation, of the two programs :func:`nsga_jax.simulate`
compiles (the preparation and the chunk of steps).

Each scene runs in a fresh process with the compilation cache off (cold), in
its default configuration::

    python experiments/benchmarks/bench_compile.py [--scenes bouncing_ball,impacting_bar] [--out DIR]

prints and writes ``DIR/compile.md``: per scene, the chunk program's size
(equations of its jaxpr, nested ones included), the seconds of tracing it
(``jax.make_jaxpr``), of tracing and lowering it (``lower``), and of XLA's
compilation (``compile``), and the same three for the preparation. Then,
warm: two more fresh processes with nsga_jax's persistent compilation cache
in a new folder, the first filling it, the second loading both programs from
it (``use_compilation_cache``, as the command line does); the second's
tracing, lowering and loading of both programs together, and its loading
alone.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def _equations(jaxpr) -> int:
    """Equations of a jaxpr, counting those of the jaxprs nested in its
    equations (loops, conditionals, calls)."""
    import jax

    count = 0
    for eqn in jaxpr.eqns:
        count += 1
        for value in eqn.params.values():
            for sub in value if isinstance(value, (list, tuple)) else (value,):
                if isinstance(sub, jax.extend.core.ClosedJaxpr):
                    count += _equations(sub.jaxpr)
                elif isinstance(sub, jax.extend.core.Jaxpr):
                    count += _equations(sub)
    return count


def measure(scene_name: str) -> dict:
    """One scene's compile phases, in this process (cold: run it in a fresh one)."""
    import equinox as eqx
    import jax
    import jax.numpy as jnp

    import nsga_jax as nj
    from nsga_jax._precision import cast_floats
    from nsga_jax._run_core import prepare_and_init, run_chunk
    from nsga_jax._simulate import chunk_length

    scene = nj.load_scene(scene_name)
    dtype = scene.solver["dtype"]
    model, scheme = cast_floats((scene.model, scene.scheme()), dtype)
    h = scene.solver["h"]
    args0 = (model, scheme, jnp.asarray(0.0, dtype), jnp.asarray(scene.q0, dtype), jnp.asarray(scene.v0, dtype),
             jnp.asarray(h, dtype))
    out: dict = {"scene": scene_name, "n_dof": int(model.n_dof)}

    def phases(name, fn, args, static):
        jitted = eqx.filter_jit(fn)
        dynamic, rest = eqx.partition(args, eqx.is_array)
        t = time.perf_counter()
        closed = jax.make_jaxpr(lambda d: fn(*eqx.combine(d, rest), *static))(dynamic)
        out[f"{name}_trace_s"] = time.perf_counter() - t
        out[f"{name}_equations"] = _equations(closed.jaxpr)
        t = time.perf_counter()
        lowered = jitted.lower(*args, *static)
        out[f"{name}_lower_s"] = time.perf_counter() - t
        t = time.perf_counter()
        compiled = lowered.compile()
        out[f"{name}_compile_s"] = time.perf_counter() - t
        return compiled

    prep = phases("prepare", prepare_and_init, args0, ())
    ops, state = prep(*args0)
    length = chunk_length(model)
    real = jnp.dtype(dtype).type
    chunk_args = (model, scheme, ops, state, jnp.asarray(h, dtype), jnp.asarray(real(0.0)),
                  jnp.asarray(length, jnp.int32), jnp.asarray(False))
    phases("chunk", run_chunk, chunk_args, (length,))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", default="all")
    parser.add_argument("--out", default="experiments/out/compile")
    parser.add_argument("--one", help=argparse.SUPPRESS)  # the child process: measure this scene, print JSON
    parser.add_argument("--cache", help=argparse.SUPPRESS)  # the child's persistent compilation cache
    args = parser.parse_args()
    if args.one:
        from nsga_jax._process_settings import configure_jax

        configure_jax()
        if args.cache:
            from nsga_jax._compilation_cache import use_compilation_cache

            use_compilation_cache(args.cache)
        print(json.dumps(measure(args.one)))
        return
    from nsga_jax.scenes import REGISTRY

    names = sorted(REGISTRY) if args.scenes == "all" else args.scenes.split(",")
    rows = []
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}

    def child(name: str, *extra: str) -> dict | None:
        proc = subprocess.run([sys.executable, __file__, "--one", name, *extra], capture_output=True, text=True,
                              env=env)
        if proc.returncode:
            print(f"{name}: failed\n{proc.stderr[-2000:]}", file=sys.stderr)
            return None
        return json.loads(proc.stdout.strip().splitlines()[-1])

    for name in names:
        cold = child(name)
        with tempfile.TemporaryDirectory() as cache:
            fills, warm = child(name, "--cache", cache), child(name, "--cache", cache)  # the second loads
        if cold is None or fills is None or warm is None:
            continue
        cold["warm_s"] = sum(warm[f"{p}_lower_s"] + warm[f"{p}_compile_s"] for p in ("chunk", "prepare"))
        cold["warm_load_s"] = warm["chunk_compile_s"] + warm["prepare_compile_s"]
        rows.append(cold)
        r = rows[-1]
        print(f"{name}: chunk {r['chunk_equations']} eqns, trace {r['chunk_trace_s']:.2f} s, lower "
              f"{r['chunk_lower_s']:.2f} s, XLA {r['chunk_compile_s']:.2f} s; warm {r['warm_s']:.2f} s", flush=True)
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    lines = [
        f"`python experiments/benchmarks/bench_compile.py`, {datetime.date.today()}, commit {commit}, "
        f"{platform.node()} ({platform.machine()}), cold (a fresh process per scene, no compilation cache).",
        "",
        "| scene | n | chunk: equations | trace [s] | trace + lower [s] | XLA compile [s] "
        "| preparation: equations | trace [s] | trace + lower [s] | XLA compile [s] "
        "| warm: both programs' trace + lower + load [s] | of which loading [s] |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(f"| {r['scene']} | {r['n_dof']} | {r['chunk_equations']} | {r['chunk_trace_s']:.2f} | "
                     f"{r['chunk_lower_s']:.2f} | {r['chunk_compile_s']:.2f} | {r['prepare_equations']} | "
                     f"{r['prepare_trace_s']:.2f} | {r['prepare_lower_s']:.2f} | {r['prepare_compile_s']:.2f} | "
                     f"{r['warm_s']:.2f} | {r['warm_load_s']:.2f} |")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "compile.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
