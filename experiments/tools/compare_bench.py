"""``nsga-jax bench`` at two git revisions, interleaved, with the figures an
architecture change must not worsen.

    python experiments/tools/compare_bench.py BASE [HEAD] --pairs 3 --out compare.md \
        -- --scenes impacting_bar,flexible_cube --batch 1
    python experiments/tools/compare_bench.py BASE -- --scenes bouncing_ball --batch 1,1024

Each revision is checked out into a temporary worktree (HEAD defaults to the
working tree) and benchmarked in its own process, alternately (BASE, HEAD,
BASE, HEAD, ...), so that the slow and fast spells of a shared machine hit
both. Everything after ``--`` is handed to ``nsga-jax bench`` unchanged (its
own ``--repeats`` runs per configuration, the fastest kept). For every row of
the benchmark (scene, precision, batch) the table gives the best of the pairs
for each revision: µs per step, member-steps per second, the ratio of a step
to one dense factor+solve of the iteration matrix (``factor_solve_us``, where
the benchmark measures it) and the compile time [s], with HEAD/BASE ratios.
Compilation caches are off in every process.
"""

from __future__ import annotations

import argparse
import csv
import datetime
import os
import platform
import subprocess
import sys
from pathlib import Path

from compare_revisions import revision_trees  # the script next to this one

ROOT = Path(__file__).resolve().parents[2]

RUN = r"""
import sys
sys.meta_path = [f for f in sys.meta_path if "editable" not in repr(f)]  # import the given tree
sys.path.insert(0, sys.argv[1])
try:  # the command line's module, private since e60fe98
    from nsga_jax._cli import main
except ModuleNotFoundError:
    from nsga_jax.cli import main
sys.exit(main(["bench", *sys.argv[2:]]))
"""

KEY = ("scene", "dtype", "batch")
COLUMNS = ("us_per_step", "member_steps_per_s", "step_per_factor_solve", "compile_s")
BETTER_HIGH = {"member_steps_per_s"}


def bench(tree: Path, bench_args: list[str], out: Path) -> list[dict]:
    subprocess.run([sys.executable, "-c", RUN, str(tree), *bench_args, "--out", str(out)], check=True,
                   env={**os.environ, "NSGA_JAX_CACHE": "off"}, stdout=subprocess.DEVNULL)
    rows = []
    with open(out / "bench.csv") as f:
        for row in csv.DictReader(f):
            values = {c: float(row[c]) for c in ("us_per_step", "member_steps_per_s", "compile_s")}
            fs = row.get("factor_solve_us") or ""
            measured = fs not in ("", "nan")
            values["step_per_factor_solve"] = float(row["us_per_step"]) / float(fs) if measured else float("nan")
            rows.append({**{k: row[k] for k in KEY}, **values})
    return rows


def best(values: list[float], column: str) -> float:
    finite = [v for v in values if v == v]
    if not finite:
        return float("nan")
    return max(finite) if column in BETTER_HIGH else min(finite)


def main() -> None:
    argv = sys.argv[1:]
    bench_args = argv[argv.index("--") + 1:] if "--" in argv else []
    argv = argv[: argv.index("--")] if "--" in argv else argv
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("base", help="git revision to compare against")
    parser.add_argument("head", nargs="?", default=None, help="git revision (default: the working tree)")
    parser.add_argument("--pairs", type=int, default=3)
    parser.add_argument("--out", type=Path, default=None, help="also write the table (Markdown) here")
    args = parser.parse_args(argv)
    commit = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", args.head or "HEAD"],
                            capture_output=True, text=True, check=True).stdout.strip()
    with revision_trees(args.base, args.head, "nsga_jax_bench_") as (trees, tmp):
        runs: dict[str, list[list[dict]]] = {"base": [], "head": []}
        for i in range(args.pairs):
            for label in ("base", "head"):
                rows = bench(trees[label], bench_args, tmp / f"{label}{i}")
                runs[label].append(rows)
                print(label, i, " | ".join(f"{r['scene']} {r['dtype']} b{r['batch']}: {r['us_per_step']:.1f} µs"
                                           for r in rows), flush=True)
    keys = [tuple(r[k] for k in KEY) for r in runs["base"][0]]
    lines = [f"`compare_bench.py {args.base} {args.head or commit + ' (working tree)'} --pairs {args.pairs} -- "
             f"{' '.join(bench_args)}`, {datetime.date.today()}, {platform.node()} ({os.cpu_count()} CPUs); "
             "best of the pairs per revision; ratio = HEAD / BASE.", "",
             "| scene | dtype | batch | " + " | ".join(f"{c} base | head | ratio" for c in COLUMNS) + " |",
             "|" + "---|" * (3 + 3 * len(COLUMNS))]
    for key in keys:
        cells = list(key)
        for c in COLUMNS:
            b = best([r[c] for rows in runs["base"] for r in rows if tuple(r[k] for k in KEY) == key], c)
            h = best([r[c] for rows in runs["head"] for r in rows if tuple(r[k] for k in KEY) == key], c)
            cells += [f"{b:.4g}", f"{h:.4g}", f"{h / b:.3f}" if b == b and b else ""]
        lines.append("| " + " | ".join(cells) + " |")
    table = "\n".join(lines)
    print(table)
    if args.out is not None:
        args.out.write_text(table + "\n")


if __name__ == "__main__":
    main()
