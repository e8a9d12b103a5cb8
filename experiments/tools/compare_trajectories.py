"""Whether two git revisions compute the same trajectories, bit for bit.

    python experiments/tools/compare_trajectories.py BASE [HEAD] [--scenes a,b] [--schemes ds,dsn,cs,mj]
        [--set impacts=instants ...]

Each revision is checked out into a temporary worktree (HEAD defaults to the
working tree) and runs every (scene, scheme) for a short window in its own
process, at float64, from its scene's defaults; the script then compares q,
v and the impulses array by array and prints, for each pair, ``bitwise``,
the largest difference, or what failed. A refactoring must leave every
array bitwise equal; a change of method says by how much it moved.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from compare_revisions import revision_trees  # noqa: E402  (the script next to this one)

RUN = r"""
import json, os, sys
sys.meta_path = [f for f in sys.meta_path if "editable" not in repr(f)]  # import the given tree
sys.path.insert(0, sys.argv[1])
os.environ["JAX_ENABLE_X64"] = "1"
import numpy as np
import nsga_jax
out, settings = sys.argv[2], json.loads(sys.argv[3])
for spec in sys.argv[4:]:
    scene_name, scheme, t_end = spec.split(":")
    try:
        scene = nsga_jax.load_scene(scene_name, {"scheme": scheme, "t_end": float(t_end), **settings})
        sol = scene.run(throw=False)
        np.savez(f"{out}/{scene_name}-{scheme}.npz", q=np.asarray(sol.q), v=np.asarray(sol.v),
                 impulse=np.asarray(sol.impulse))
    except Exception as error:  # reported, the next pair goes on
        print(f"{scene_name}-{scheme}: {type(error).__name__}: {error}", file=sys.stderr)
"""

WINDOWS = {"bouncing_ball": 0.5, "rigid_pendulum": 0.5, "rigid_box": 0.3, "double_pendulum": 0.3,
           "impacting_bar": 0.6, "flexible_pendulum": 0.05, "flexible_cube": 0.003, "slider_crank": 0.05,
           "newtons_cradle": 0.3, "incline": 0.2, "rocking_block": 0.3, "box_stack": 0.05,
           "flexible_appendage": 0.05}
"""Each scene's window [s]: through its first impacts, a few seconds of running a scheme."""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("base")
    parser.add_argument("head", nargs="?", default=None)
    parser.add_argument("--scenes", default=",".join(WINDOWS))
    parser.add_argument("--schemes", default="ds,dsn,cs,mj")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="a setting of every run (a solver setting or parameter; VALUE read as JSON, else text)")
    args = parser.parse_args()
    settings = {}
    for item in args.set:
        key, _, value = item.partition("=")
        try:
            settings[key] = json.loads(value)
        except json.JSONDecodeError:
            settings[key] = value
    specs = [f"{s}:{k}:{WINDOWS[s]}" for s in args.scenes.split(",") for k in args.schemes.split(",")]
    with revision_trees(args.base, args.head, "nsga-trajectories-") as (trees, tmp), \
            tempfile.TemporaryDirectory() as outs:
        for label, tree in trees.items():
            Path(outs, label).mkdir()
            subprocess.run([sys.executable, "-c", RUN, str(tree), str(Path(outs, label)), json.dumps(settings),
                            *specs], check=True,
                           env={**os.environ, "NSGA_JAX_CACHE": "off"})
        same = 0
        for spec in specs:
            name = "-".join(spec.split(":")[:2])
            files = [Path(outs, label, f"{name}.npz") for label in ("base", "head")]
            if not all(f.exists() for f in files):
                print(f"{name:34s} missing at {', '.join(f.parent.name for f in files if not f.exists())}")
                continue
            a, b = (np.load(f) for f in files)
            diffs = {k: (float(np.abs(a[k] - b[k]).max()) if a[k].shape == b[k].shape and a[k].size else
                         (0.0 if a[k].shape == b[k].shape else float("inf"))) for k in a.files}
            bitwise = all(a[k].shape == b[k].shape and np.array_equal(a[k], b[k]) for k in a.files)
            same += bitwise
            print(f"{name:34s} " + ("bitwise" if bitwise else
                                    "max |diff| " + ", ".join(f"{k} {d:.3g}" for k, d in diffs.items())))
        print(f"{same} of {len(specs)} runs bitwise equal")


if __name__ == "__main__":
    main()
