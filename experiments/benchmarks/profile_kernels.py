"""Where a compiled DS step of the chain of ``bench_chain.py`` spends its
kernels on a CPU: XLA's per-kernel trace (``--xla_cpu_enable_xprof_traceme``,
set here before JAX loads) over one compiled run, counted per step and
grouped by kernel kind (the fusion's name without its number).

The profiler's own cost inflates every kernel (a step takes several times
its unprofiled time), so the times are for ranking; the launch counts are
exact. On a CPU a small system's step costs about its number of kernel
launches: this is what a change to the step's structure should lower.

    python experiments/benchmarks/profile_kernels.py [--links 50] [--steps 200] [--top 25]
"""

from __future__ import annotations

import argparse
import collections
import glob
import gzip
import json
import os
import re
import sys
import tempfile
import time
from pathlib import Path

os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "") + " --xla_cpu_enable_xprof_traceme=true").strip()

import jax  # noqa: E402

from nsga_jax._process_settings import configure_jax  # noqa: E402

configure_jax()

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_chain import chain  # noqa: E402


def kernel_events(trace_dir: str) -> list[dict]:
    """The complete events of the Perfetto trace under ``trace_dir``, less the executor's own."""
    path = glob.glob(f"{trace_dir}/**/*.trace.json.gz", recursive=True)[0]
    events = json.load(gzip.open(path))
    events = events["traceEvents"] if isinstance(events, dict) else events
    return [e for e in events if e.get("ph") == "X" and not e["name"].startswith(("ThunkExecutor", "while", "end: "))]


def main() -> None:
    import nsga_jax as nj

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--links", type=int, default=50)
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--top", type=int, default=25)
    args = parser.parse_args()
    model, q0, v0 = chain(args.links)
    steps = args.steps
    run = jax.jit(lambda q, v: nj.integrate(model, nj.DS(), 0.0, steps * 1e-3, 1e-3, q, v,
                                            saveat=nj.SaveAt(every=steps)).q[-1])
    jax.block_until_ready(run(q0, v0))
    start = time.perf_counter()
    jax.block_until_ready(run(q0, v0))
    unprofiled = (time.perf_counter() - start) / steps * 1e6
    options = jax.profiler.ProfileOptions()
    options.python_tracer_level = 0
    with tempfile.TemporaryDirectory() as trace_dir:
        jax.profiler.start_trace(trace_dir, create_perfetto_trace=True, profiler_options=options)
        jax.block_until_ready(run(q0, v0))
        jax.profiler.stop_trace()
        events = kernel_events(trace_dir)
    launches, micros = collections.Counter(), collections.Counter()
    for e in events:
        kind = re.sub(r"\.\d+$", "", e["name"])
        launches[kind] += 1
        micros[kind] += e.get("dur", 0)
    print(f"chain of {args.links} links, DS, {steps} steps: {unprofiled:.0f} µs a step unprofiled, "
          f"{len(events) / steps:.0f} kernel launches a step")
    print("| kernel kind | launches a step | profiled µs a step |")
    print("|---|---|---|")
    for kind, count in launches.most_common(args.top):
        print(f"| {kind} | {count / steps:.1f} | {micros[kind] / steps:.0f} |")


if __name__ == "__main__":
    main()
