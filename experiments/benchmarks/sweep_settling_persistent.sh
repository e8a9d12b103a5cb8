#!/usr/bin/env bash
# The rocking block with persistent_contacts = "smooth" over six tilts and three steps, 5 s each
# (docs/friction.md, *Persistent contacts in the smooth motion*, where it does not come to rest):
# failed steps, Newton solves a step (max), |theta| and |omega| at the end.
#   bash experiments/benchmarks/sweep_settling_persistent.sh [OUT_DIR]
set -euo pipefail
out=${1:-$(mktemp -d)}
echo "| h [s] | tilt [rad] | failed steps | solves a step, max | final abs(theta) [rad] | final abs(omega) [rad/s] |"
echo "|---|---|---|---|---|---|"
for h in 1e-3 2e-3 4e-3; do
  nsga-jax sweep rocking_block --grid tilt=0.05:0.3:6 --set persistent_contacts=smooth --set t_end=5 \
    --set h="$h" --out "$out/h$h" --quiet > /dev/null
  python - "$out/h$h/sweep.csv" "$h" <<'PY'
import csv, sys
for r in csv.DictReader(open(sys.argv[1])):
    print(f"| {sys.argv[2]} | {float(r['tilt']):.2f} | {r['failed_steps']} | {r['solves_per_step_max']} | "
          f"{abs(float(r['theta_final'])):.1e} | {abs(float(r['omega_final'])):.1e} |")
PY
done
