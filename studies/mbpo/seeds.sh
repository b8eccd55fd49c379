#!/usr/bin/env bash
# Three seeds of `train --algorithm mbpo` (each from its own committed planner, datacenter-2zone-mpc-seed<N>), then
# their policies over full years on the five weathers (IL and VA held out) against the building's own controls.
#
#   PREFIX=q EXTRA='--batch-size 2688 --sac ent_coef=0.05 --mbpo gradient_steps=8' bash studies/mbpo/seeds.sh
#
# A seed whose run finished (runs/<PREFIX><N>/model.zip) is not trained again; the year's evaluation is one
# `evaluate` of all three under one label, so its tables hold their mean and the intervals over the seeds
# (WORK/year-<PREFIX>/). PREFIX names the recipe's runs (default s); WORK, STEPS, BUILDING, TARGET, EXTRA as
# pilot.sh's; YEAR_DAYS the evaluation's days (365; the CRAC data center's years are 351 days).
set -uo pipefail
cd "$(dirname "$0")/../.."
REPO=$PWD
WORK=${WORK:-$REPO/../mbpo}
P=${PREFIX:-s}
for s in 0 1 2; do
    [ -f "$WORK/runs/$P$s/model.zip" ] && continue
    NAME=$P$s SEED=$s bash studies/mbpo/pilot.sh
done
cd "$WORK"
echo "$(date -Is) year-$P" >> progress.log
"$REPO/.venv/bin/parallel-eplus" evaluate --building "${BUILDING:-datacenter-2zone}" --baseline \
  --policy "runs/${P}0/model.zip=MBPO" --policy "runs/${P}1/model.zip=MBPO" --policy "runs/${P}2/model.zip=MBPO" \
  --weathers CA,CO,FL,IL,VA --run-days "${YEAR_DAYS:-365}" --workers 2 --out "year-$P" --quiet > "year-$P.log" 2>&1
echo "$(date -Is) year-$P done (rc=$?)" >> progress.log
