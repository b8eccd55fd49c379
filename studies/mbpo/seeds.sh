#!/usr/bin/env bash
# Three seeds of `train --algorithm mbpo` (each from its own committed planner, datacenter-2zone-mpc-seed<N>), then
# their policies over full years on the five weathers (IL and VA held out) against the building's own controls.
#
#   EXTRA='--batch-size 2688 --mbpo gradient_steps=8' bash studies/mbpo/seeds.sh
#
# A seed whose run finished (runs/s<N>/model.zip) is not trained again; the year's evaluation is one `evaluate` of
# all three under one label, so its tables hold their mean and the intervals over the seeds (WORK/year/).
# WORK, STEPS, EXTRA as pilot.sh's.
set -uo pipefail
cd "$(dirname "$0")/../.."
REPO=$PWD
WORK=${WORK:-$REPO/../mbpo}
for s in 0 1 2; do
    [ -f "$WORK/runs/s$s/model.zip" ] && continue
    NAME=s$s SEED=$s bash studies/mbpo/pilot.sh
done
cd "$WORK"
echo "$(date -Is) year" >> progress.log
"$REPO/.venv/bin/parallel-eplus" evaluate --building datacenter-2zone --baseline --policy runs/s0/model.zip=MBPO \
  --policy runs/s1/model.zip=MBPO --policy runs/s2/model.zip=MBPO --weathers CA,CO,FL,IL,VA --run-days 365 \
  --workers 2 --out year --quiet > year.log 2>&1
echo "$(date -Is) year done (rc=$?)" >> progress.log
