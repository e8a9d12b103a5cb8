"""Where a sweep's time goes outside its compiled batches.

Runs one sweep of 32 × 32 = 1,024 members (the bouncing ball over e and the
drop height, 1 s each; or the impacting bar over e and E, 0.2 s each) into a
fresh folder with cProfile on, and prints the end-to-end and in-batch
member-steps per second, the compile time, and the cumulative seconds of the
host phases (validating and building the members' models, grouping them by
structure, stacking them, summarising each member's row, the plot)::

    python experiments/benchmarks/bench_sweep_overhead.py [--scene bouncing_ball|impacting_bar]
        [--out experiments/out/sweep_overhead]

Writes ``sweep_overhead.md`` (the table) and ``profile.txt`` (the 60 most
expensive calls, cumulative) in ``--out``. Profiling adds its own overhead to
the host phases (about a fifth); the batches' wall and compile times are
those the sweep measures itself.
"""

from __future__ import annotations

import argparse
import cProfile
import datetime
import io
import platform
import pstats
import tempfile
import time
from pathlib import Path

import numpy as np

import nsga_jax as nj

GRIDS = {
    "bouncing_ball": ({"e": np.linspace(0.1, 0.9, 32), "height": np.linspace(0.5, 1.5, 32)}, {"t_end": 1.0}),
    "impacting_bar": ({"e": np.linspace(0.1, 0.9, 32), "E": np.linspace(800, 1000, 32)}, {"t_end": 0.2}),
}
PHASES = {  # name in the table: the profiled function (file suffix, function name)
    "validate members (grid.members)": ("_grid.py", "members"),
    "build members' models one by one": ("_scenes/spec.py", "build"),
    "group by structure (split_batches)": ("_sweep_build.py", "split_batches"),
    "build the batches' models (build_batch)": ("_sweep_build.py", "build_batch"),
    "stack models": ("_batch.py", "stack_models"),
    "batches incl. compile (BatchRun)": ("_batch.py", "__init__"),
    "join the records to the initial rows (joined_records)": ("_batch.py", "joined_records"),
    "observables (sweep_build)": ("_sweep_build.py", "observables_of"),
    "rows (_row)": ("_sweep_batches.py", "_row"),
    "member solutions": ("_batch.py", "member_solution"),
    "plot": ("_sweep.py", "plot_sweep"),
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="bouncing_ball", choices=sorted(GRIDS))
    parser.add_argument("--out", default="experiments/out/sweep_overhead")
    args = parser.parse_args()
    nj.configure_jax()
    from nsga_jax._sweep import sweep

    grid, overrides = GRIDS[args.scene]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    profile = cProfile.Profile()
    with tempfile.TemporaryDirectory(prefix="nsga_jax_sweep_") as tmp:
        start = time.perf_counter()
        profile.enable()
        result = sweep(args.scene, grid, overrides=overrides, out=Path(tmp) / "sweep")
        profile.disable()
        total = time.perf_counter() - start
    stats = pstats.Stats(profile)
    cumulative = {}
    for (path, _, name), (_, _, _, cum, _) in stats.stats.items():  # type: ignore[attr-defined]
        for phase, (suffix, function) in PHASES.items():
            if path.endswith(suffix) and name == function:
                cumulative[phase] = cumulative.get(phase, 0.0) + cum
    steps = sum(int(r["n_steps"]) for r in result.rows)
    lines = [
        f"`python experiments/benchmarks/bench_sweep_overhead.py --scene {args.scene}`, "
        f"{datetime.date.today()}, {platform.node()} ({platform.processor() or platform.machine()}); "
        f"{len(result.rows)} members, {steps:,} member-steps.",
        "",
        "| what | seconds |",
        "|---|---|",
        f"| end to end | {total:.2f} |",
        f"| batches' wall time | {result.wall_time:.2f} |",
        f"| batches' compile time | {result.compile_time:.2f} |",
        *(f"| {phase} | {cumulative.get(phase, 0.0):.2f} |" for phase in PHASES),
        "",
        f"End to end {steps / total:.3g} member-steps/s; in the batches {steps / result.wall_time:.3g} "
        f"({100 * result.wall_time / total:.1f} % of the time).",
    ]
    text = "\n".join(lines)
    print(text)
    (out / "sweep_overhead.md").write_text(text + "\n")
    buffer = io.StringIO()
    pstats.Stats(profile, stream=buffer).sort_stats("cumulative").print_stats(60)
    (out / "profile.txt").write_text(buffer.getvalue())


if __name__ == "__main__":
    main()
