"""OpenBLAS threads of the command line: a run's time per step with
``OPENBLAS_NUM_THREADS=1`` (what ``nsga-jax`` sets unless the user did)
against 2 (OpenBLAS's own default on a 2-core machine), interleaved.

    python experiments/benchmarks/blas_threads.py [--scenes flexible_cube,impacting_bar] [--pairs 3] [--load 1]

Each pair runs the command line once with each setting, in separate
processes, alternating which goes first; ``--load N`` keeps N busy Python
processes running meanwhile (a machine whose cores are busy, where OpenBLAS's
spinning threads hurt most). Compiled programs come from a persistent cache
in a temporary folder, so the timings are the runs'. Prints a Markdown table
of the median µs/step per setting and writes it to
``experiments/out/blas_threads.md``.
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

CASES = {
    "flexible_cube": ["--t-end", "0.003"],
    "impacting_bar": ["--t-end", "0.5"],
    "flexible_pendulum": ["--t-end", "0.05"],
}


def run(scene: str, threads: str, cache: str, out: str) -> float:
    env = {**os.environ, "OPENBLAS_NUM_THREADS": threads, "NSGA_JAX_CACHE": cache}
    proc = subprocess.run([sys.executable, "-m", "nsga_jax._cli", "run", scene, *CASES[scene], "--out", out,
                           "--overwrite", "--quiet"], env=env, capture_output=True, text=True, timeout=900)
    found = re.search(r"\(([\d.]+) us/step\)", proc.stdout)
    if proc.returncode != 0 or not found:
        raise RuntimeError(proc.stderr[-2000:])
    return float(found.group(1))


BUSY = "import time\nend = time.time() + 3600\nwhile time.time() < end:\n    sum(i * i for i in range(10_000))\n"
"""A process that keeps one core busy for at most an hour."""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--scenes", default="flexible_cube,impacting_bar")
    parser.add_argument("--pairs", type=int, default=3)
    parser.add_argument("--load", type=int, default=1, help="busy processes running meanwhile")
    args = parser.parse_args()
    loads = [subprocess.Popen([sys.executable, "-c", BUSY]) for _ in range(args.load)]
    rows = []
    try:
        with tempfile.TemporaryDirectory() as tmp:
            for scene in args.scenes.split(","):
                out = str(Path(tmp) / scene)
                run(scene, "1", tmp + "/cache", out)  # warm-up: fills the compilation cache
                times: dict[str, list[float]] = {"1": [], "2": []}
                for pair in range(args.pairs):
                    for threads in (("1", "2") if pair % 2 == 0 else ("2", "1")):
                        times[threads].append(run(scene, threads, tmp + "/cache", out))
                one, two = statistics.median(times["1"]), statistics.median(times["2"])
                runs = [", ".join(f"{t:.0f}" for t in times[k]) for k in ("1", "2")]
                rows.append(f"| {scene} | {one:.1f} | {two:.1f} | {two / one:.2f} | {runs[0]} | {runs[1]} |")
                print(rows[-1], flush=True)
    finally:
        for p in loads:
            p.kill()
    table = "\n".join(["| scene | 1 thread [µs/step] | 2 threads [µs/step] | ratio | runs (1) | runs (2) |",
                       "|---|---|---|---|---|---|", *rows])
    header = (f"{time.strftime('%Y-%m-%d')}, {os.cpu_count()} cores, {args.load} busy process(es), "
              f"{args.pairs} interleaved pairs, median µs/step\n\n")
    out = Path(__file__).resolve().parents[1] / "out"
    out.mkdir(exist_ok=True)
    (out / "blas_threads.md").write_text(header + table + "\n")
    print(header + table)


if __name__ == "__main__":
    main()
