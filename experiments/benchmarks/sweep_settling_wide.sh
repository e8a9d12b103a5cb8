#!/usr/bin/env bash
# The rocking block over 16 tilts (0.02 to 0.32 rad), 5 s each, for each friction coefficient, step and
# way of carrying persistent contacts (docs/friction.md, *Persistent contacts in the smooth motion*):
# per sweep of 16 runs, the failed steps, the runs not flat at the end (|theta| > 1e-12 rad) and the
# most Newton solves in a step.
#   bash experiments/benchmarks/sweep_settling_wide.sh [OUT_DIR]
set -euo pipefail
out=${1:-$(mktemp -d)}
echo "| contacts in | impacts at | mu | h [s] | runs | failed steps | not flat at 5 s (tilt: abs(theta) [rad]) | solves a step, max |"
echo "|---|---|---|---|---|---|---|---|"
row() {  # contacts impacts mu h
  local dir="$out/$1_$2_$3_$4"
  nsga-jax sweep rocking_block --grid tilt=0.02:0.32:16 --set persistent_contacts="$1" --set impacts="$2" \
    --set mu="$3" --set t_end=5 --set h="$4" --out "$dir" --quiet > /dev/null 2>&1
  python - "$dir/sweep.csv" "$@" <<'PY'
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1])))
failed = sum(int(r["failed_steps"]) for r in rows)
moving = [f"{float(r['tilt']):.2f}: {abs(float(r['theta_final'])):.1e}" for r in rows
          if abs(float(r["theta_final"])) > 1e-12]
solves = max(int(r["solves_per_step_max"]) for r in rows)
print(f"| {sys.argv[2]} | {sys.argv[3]} | {sys.argv[4]} | {sys.argv[5]} | {len(rows)} | {failed} | "
      f"{', '.join(moving) or 'none'} | {solves} |")
PY
}
for mu in 0.5 1e4; do
  for h in 1e-3 2e-3 4e-3; do
    row jumps end "$mu" "$h"
    row smooth end "$mu" "$h"
  done
done
for h in 1e-3 2e-3 4e-3; do
  row smooth instants 0.5 "$h"
done
