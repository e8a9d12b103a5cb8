"""XLA's concurrency-optimised CPU scheduler on and off: per-step and compile
time of ``nsga-jax bench`` runs, the two settings alternating run by run.

The command line and ``nsga_jax.configure_jax()`` turn the scheduler off
(importing nsga_jax does not). This measures what that gains or costs, each
run a fresh process with no compilation cache::

    python experiments/benchmarks/bench_xla_scheduler.py [--pairs 3] [--scenes impacting_bar,double_pendulum]
        [--out experiments/out/xla_scheduler]

Prints each run as it finishes, then a table of the medians (us a step and
compile s for batch 1 and 64, the ratio off/on), and writes
``xla_scheduler.csv`` (every run) and ``xla_scheduler.md`` (the medians).
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from nsga_jax._tables import read_csv, write_csv

FLAG = "--xla_cpu_enable_concurrency_optimized_scheduler"
SETTINGS = {"off": f"{FLAG}=false", "on": f"{FLAG}=true"}


def one_run(scene: str, setting: str, batches: str, steps: int) -> list[dict]:
    """The bench rows of one fresh process with the scheduler ``setting``."""
    with tempfile.TemporaryDirectory(prefix="nsga_jax_xla_") as tmp:
        env = {**os.environ, "XLA_FLAGS": f"{os.environ.get('XLA_FLAGS', '')} {SETTINGS[setting]}".strip(),
               "NSGA_JAX_CACHE": "off"}
        subprocess.run([sys.executable, "-m", "nsga_jax._cli", "bench", "--scenes", scene, "--batch", batches,
                        "--max-steps", str(steps), "--repeats", "3", "--out", tmp], env=env, check=True,
                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=900)
        return [{**row, "scheduler": setting} for row in read_csv(Path(tmp) / "bench.csv")]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--pairs", type=int, default=3)
    parser.add_argument("--scenes", default="impacting_bar,double_pendulum,rigid_box")
    parser.add_argument("--batch", default="1,64")
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--out", type=Path, default=Path("experiments/out/xla_scheduler"))
    args = parser.parse_args()
    rows: list[dict] = []
    for pair in range(args.pairs):
        for scene in args.scenes.split(","):
            order = ("off", "on") if pair % 2 == 0 else ("on", "off")  # alternate which goes first
            for setting in order:
                for row in one_run(scene, setting, args.batch, args.steps):
                    rows.append({"pair": pair, **row})
                    print(f"pair {pair} {scene:16s} batch {row['batch']:>4} scheduler {setting:3s} "
                          f"{float(row['us_per_step']):9.1f} us/step, compile {float(row['compile_s']):6.2f} s",
                          flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    write_csv(args.out / "xla_scheduler.csv", rows)
    lines = [f"XLA CPU scheduler off against on; medians of {args.pairs} alternating fresh processes; "
             f"bench_xla_scheduler.py --pairs {args.pairs} --scenes {args.scenes} --batch {args.batch}; "
             f"{datetime.date.today()}, {platform.machine()}, {os.cpu_count()} cores", "",
             "| scene | batch | us/step off | us/step on | off/on | compile off [s] | compile on [s] |",
             "|---|---|---|---|---|---|---|"]
    for scene in args.scenes.split(","):
        for batch in args.batch.split(","):
            def median(setting: str, key: str) -> float:
                return statistics.median(float(r[key]) for r in rows if r["scene"] == scene
                                         and str(r["batch"]) == batch and r["scheduler"] == setting)
            off, on = median("off", "us_per_step"), median("on", "us_per_step")
            lines.append(f"| {scene} | {batch} | {off:.1f} | {on:.1f} | {off / on:.3f} | "
                         f"{median('off', 'compile_s'):.2f} | {median('on', 'compile_s'):.2f} |")
    table = "\n".join(lines) + "\n"
    (args.out / "xla_scheduler.md").write_text(table)
    print(table)


if __name__ == "__main__":
    main()
