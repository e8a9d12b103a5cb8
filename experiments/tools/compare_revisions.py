"""A scene's per-step time and compile work at two git revisions, interleaved.

    python experiments/tools/compare_revisions.py BASE [HEAD] --scene flexible_pendulum [--pairs 4]
        [--batch 64] [--cpus 1]

Each revision is checked out into a temporary worktree and run in its own
process, alternately (BASE, HEAD, BASE, HEAD, ...), so that the slow and fast
spells of a shared machine hit both; HEAD defaults to the working tree. Each
process reports the scene's ``nsga-jax bench`` case run 4 times (fastest
µs/step of whole runs, compile apart) and, with ``--batch B``, the process
CPU time of compiling a batch of B members (XLA's code generation runs on
several threads, so CPU time is steadier than wall time). Prints one line per
process and the minimum of each column per revision.

``--cpus N`` runs every process on N CPUs only (``os.sched_setaffinity``).
XLA's CPU runtime runs independent operations of a program on its worker
threads, and whether that helps or costs on a machine with few cores
depends on the shape of each program's dependency graph. Two versions of
the flexible pendulum's step (element tangents by ``jacfwd``, and in closed
form) measured 45-63 against 80-99 µs per step on 2 CPUs, and 55-81 against
56-62 pinned to one (four interleaved pairs each). ``--cpus 1`` measures
the work a change saves without that effect; the default (every CPU) what
a user of this machine gets. Report both when they disagree.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

# The child imports the private helpers _bench_scene, BatchRun, broadcast_members and step_count on purpose:
# they exist under these names in every revision this script compares, in modules that became private
# (_bench, _batch, _validation) in e60fe98: a revision before it has them public.
MEASURE = r"""
import json, os, sys, time
sys.meta_path = [f for f in sys.meta_path if "editable" not in repr(f)]  # import the given tree
sys.path.insert(0, sys.argv[1])
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ["JAX_ENABLE_X64"] = "1"  # float64 (a revision that turns it on at import does too)
import importlib
import numpy as np
def module(name):  # private since e60fe98, public before
    try:
        return importlib.import_module(f"nsga_jax._{name}")
    except ModuleNotFoundError:
        return importlib.import_module(f"nsga_jax.{name}")
_bench_scene = module("bench")._bench_scene
scene = _bench_scene(sys.argv[2], {"scheme": "ds"}, 2000)
runs = [scene.run(dtype="float64", throw=False) for _ in range(4)]
row = {"us_per_step": min(1e6 * r.wall_time / r.n_steps for r in runs), "compile_s": runs[0].compile_time}
batch = int(sys.argv[3])
if batch > 1:
    BatchRun, broadcast_members = module("batch").BatchRun, module("batch").broadcast_members
    _n_steps = module("validation").step_count
    n = _n_steps(0.0, scene.solver["t_end"], scene.solver["h"])
    cpu = time.process_time()
    run = BatchRun(broadcast_members(scene.model, batch), scene.scheme(), 0.0, np.tile(scene.q0, (batch, 1)),
                   np.tile(scene.v0, (batch, 1)), np.full(batch, scene.solver["h"]), np.full(batch, n))
    row.update(batch_compile_s=run.compile_time, batch_compile_cpu_s=time.process_time() - cpu)
print(json.dumps(row))
"""



@contextlib.contextmanager
def revision_trees(base: str, head: str | None, prefix: str) -> Iterator[tuple[dict[str, Path], Path]]:
    """``({"base": tree, "head": tree}, tmp)``: each revision checked out into a
    temporary worktree (``head=None``: the working tree itself) inside the
    temporary folder ``tmp``; the worktrees are removed on exit."""
    with tempfile.TemporaryDirectory(prefix=prefix) as tmp:
        trees: dict[str, Path] = {}
        try:
            for label, rev in (("base", base), ("head", head)):
                if rev is None:
                    trees[label] = ROOT
                    continue
                trees[label] = Path(tmp) / label
                subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", "-q", str(trees[label]),
                                rev], check=True)
            yield trees, Path(tmp)
        finally:
            for tree in trees.values():
                if tree != ROOT:
                    subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(tree)], check=False)

def measure(tree: Path, scene: str, batch: int, cpus: int | None = None) -> dict:
    pin = None if cpus is None else (lambda: os.sched_setaffinity(0, sorted(os.sched_getaffinity(0))[:cpus]))
    out = subprocess.run([sys.executable, "-c", MEASURE, str(tree), scene, str(batch)], check=True,
                         capture_output=True, text=True, env={**os.environ, "NSGA_JAX_CACHE": "off"},
                         preexec_fn=pin)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("base", help="git revision to compare against")
    parser.add_argument("head", nargs="?", default=None, help="git revision (default: the working tree)")
    parser.add_argument("--scene", required=True)
    parser.add_argument("--pairs", type=int, default=4)
    parser.add_argument("--batch", type=int, default=1, help="also compile a batch of this many members")
    parser.add_argument("--cpus", type=int, default=None, help="run each process on this many CPUs only")
    args = parser.parse_args()
    if args.cpus is not None and not 1 <= args.cpus <= len(os.sched_getaffinity(0)):
        parser.error(f"--cpus must be in [1, {len(os.sched_getaffinity(0))}], got {args.cpus}")
    with revision_trees(args.base, args.head, "nsga_jax_revisions_") as (trees, _):
        rows: dict[str, list[dict]] = {"base": [], "head": []}
        for _ in range(args.pairs):
            for label in ("base", "head"):
                row = measure(trees[label], args.scene, args.batch, args.cpus)
                rows[label].append(row)
                print(label, " ".join(f"{k} {v:.2f}" for k, v in row.items()), flush=True)
    for label, rs in rows.items():
        print(f"{label} ({args.base if label == 'base' else args.head or 'working tree'}): min",
              " ".join(f"{k} {min(r[k] for r in rs):.2f}" for k in rs[0]),
              "| max", " ".join(f"{k} {max(r[k] for r in rs):.2f}" for k in rs[0]))


if __name__ == "__main__":
    main()
