#!/usr/bin/env bash
# Which planner settings keep the committed planners' savings and comfort at a fraction of the cost: each setting
# (candidates, iterations, elites) evaluated with the three seeds' planners of the paper's data center on the
# training weathers (CA, CO, FL; never IL or VA) over January 1-14 and BOPTEST's peak-cooling fortnight.
#   bash studies/planner-speed/settings.sh OUT "candidates=256,iterations=3,elites=32" "candidates=128,..." ...
set -euo pipefail
cd "$(dirname "$0")/../.."
out=$1; shift
runs=results/model-based/datacenter-2zone/runs
policies=()
for s in 0 1 2; do policies+=(--policy "$runs/datacenter-2zone-mpc-seed$s/best/planner=Planner"); done
for setting in "$@"; do
  name=$(echo "$setting" | tr ',=' '_-')
  for period in jan peak_cool; do
    extra=(--run-days 14)
    [ "$period" = peak_cool ] && extra=(--scenario peak_cool)
    dir="$out/$name/$period"; mkdir -p "$out/$name"
    [ -f "$dir/results.csv" ] && continue
    echo "$(date +%T) $setting $period"
    .venv/bin/parallel-eplus evaluate --building datacenter-2zone "${policies[@]}" --planner "$setting" \
      --weathers CA,CO,FL --workers 2 --quiet --out "$dir" "${extra[@]}" > "$dir.log" 2>&1 || echo "failed: $dir.log"
  done
done
