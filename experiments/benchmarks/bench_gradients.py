"""Cost of a gradient through a whole trajectory: time of ``jax.grad`` relative
to the forward run, and memory, for 1e3, 1e4 and 1e5 steps of the impacting bar.

    python experiments/benchmarks/bench_gradients.py [--steps 1000,10000,100000] [--repeat 3]

Loss: the mean square tip displacement (200 elements, h = 1e-3 s, DS; the bar
hits the wall at 0.5 s and flies off after 1.17 s), observed step by step so
that only the tip is stored. Each configuration runs in a fresh process: the
peak resident memory (ru_maxrss) is that of forward or gradient alone;
``temp MB`` is XLA's own count of the compiled program's working buffers
(memory_analysis). Times are the minimum over --repeat runs, compile apart.
Writes docs/results/gradients/bench_gradients.{csv,md}.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

import jax

from nsga_jax._process_settings import configure_jax  # noqa: E402

configure_jax()  # float64 and XLA's CPU flag, as the command line sets them

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

RESULTS = Path("docs/results/gradients")


def measure(n_steps: int, mode: str, repeat: int) -> dict:
    """In this process: compile and time the forward loss or its gradient."""
    import resource
    import time

    import jax.numpy as jnp

    import nsga_jax
    from nsga_jax.scenes import parametrize

    params, build = parametrize("impacting_bar", {"h": 1e-3}, ["E", "velocity"])

    def loss(p):
        model, q0, v0, _ = build(p)
        sol = nsga_jax.integrate(model, nsga_jax.DS(), 0.0, n_steps * 1e-3, 1e-3, q0, v0, n_steps=n_steps,
                                 saveat=nsga_jax.SaveAt(fn=lambda state, out: state.q[-1]))
        return jnp.mean(sol.records**2)

    f = loss if mode == "forward" else jax.grad(loss)
    t = time.perf_counter()
    compiled = jax.jit(f).lower(params).compile()
    compile_s = time.perf_counter() - t
    analysis = compiled.memory_analysis()
    temp = getattr(analysis, "temp_size_in_bytes", float("nan")) if analysis is not None else float("nan")
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        jax.block_until_ready(compiled(params))
        times.append(time.perf_counter() - t)
    return {"steps": n_steps, "mode": mode, "time_s": min(times), "compile_s": compile_s,
            "temp_mb": temp / 2**20, "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", default="1000,10000,100000")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--child", nargs=2, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        print(json.dumps(measure(int(args.child[0]), args.child[1], args.repeat)))
        return
    rows = []
    for n in (int(s) for s in args.steps.split(",")):
        for mode in ("forward", "grad"):
            out = subprocess.run([sys.executable, __file__, "--repeat", str(args.repeat), "--child", str(n), mode],
                                 check=True, capture_output=True, text=True).stdout
            rows.append(json.loads(out.strip().splitlines()[-1]))
            r = rows[-1]
            print(f"{n:>7} steps {mode:>7}: {r['time_s']:.3f} s ({1e6 * r['time_s'] / n:.1f} us/step), "
                  f"compile {r['compile_s']:.1f} s, temp {r['temp_mb']:.1f} MB, peak RSS {r['peak_rss_mb']:.0f} MB",
                  flush=True)
    RESULTS.mkdir(parents=True, exist_ok=True)
    keys = list(rows[0])
    with open(RESULTS / "bench_gradients.csv", "w") as fh:
        fh.write(",".join(keys) + "\n")
        for r in rows:
            fh.write(",".join(str(r[k]) for k in keys) + "\n")
    md = ["| steps | forward [s] | grad [s] | grad / forward | forward temp [MB] | grad temp [MB] | "
          "forward peak RSS [MB] | grad peak RSS [MB] |", "|---|---|---|---|---|---|---|---|"]
    for fwd, grad in zip(rows[::2], rows[1::2]):
        md.append(f"| {fwd['steps']:.0e} | {fwd['time_s']:.3f} | {grad['time_s']:.3f} | "
                  f"{grad['time_s'] / fwd['time_s']:.1f} | {fwd['temp_mb']:.1f} | {grad['temp_mb']:.1f} | "
                  f"{fwd['peak_rss_mb']:.0f} | {grad['peak_rss_mb']:.0f} |")
    (RESULTS / "bench_gradients.md").write_text("\n".join(md) + "\n")
    print("\n".join(md))


if __name__ == "__main__":
    main()
