"""Peak memory of long runs: the ball of configs/extreme/ball_long.toml over 1e4,
1e5 and 1e6 steps, keeping every step's records or every 1000th
(``record_every``; statistics still cover every step).

    python experiments/studies/long_run_memory.py [--out DIR]

Each run is a fresh process, which reports its own peak resident set size
(``ru_maxrss``) and the run's statistics. Writes DIR/long_run_memory.csv/.md.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

from nsga_jax._process_settings import configure_jax  # noqa: E402
from nsga_jax._tables import write_csv

configure_jax()  # float64 and XLA's CPU flag, as the command line sets them

CHILD = """
import json, resource
from nsga_jax.scenes import load_scene
sol = load_scene("configs/extreme/ball_long.toml", {{"t_end": {t_end}, "record_every": {k}}}).run()
st = sol.stats
print(json.dumps({{"steps": st["n_steps"], "kept": len(sol.ts), "failed": st["failed_steps"],
                  "penetration": st["max_penetration"], "wall_s": st["wall_time_s"],
                  "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}}))
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("docs/results/long_run"))
    args = ap.parse_args()
    rows = []
    for k in (1, 1000):
        for steps in (10_000, 100_000, 1_000_000):
            code = CHILD.format(t_end=steps * 1e-3, k=k)
            out = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True)
            row = {"record_every": k, **json.loads(out.stdout.strip().splitlines()[-1])}
            rows.append(row)
            print(row, flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    write_csv(args.out / "long_run_memory.csv", rows)
    lines = ["| record_every | steps | records kept | failed steps | max penetration [m] | wall [s] | peak RSS [MB] |",
             "|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['record_every']} | {r['steps']} | {r['kept']} | {r['failed']} | {r['penetration']:.1e} | "
                     f"{r['wall_s']:.1f} | {r['peak_rss_mb']:.0f} |")
    (args.out / "long_run_memory.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
