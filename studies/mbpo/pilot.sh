#!/usr/bin/env bash
# `train --algorithm mbpo` pilots (docs/model-based.md, "SAC through the model's rollouts"): one seed from the
# building's committed planner (the paper's data center unless BUILDING says), 14-day episodes on CA, CO and FL,
# then the policy against the building's own controls on January 1-14 of those weathers.
#
#   NAME=p2 EXTRA='--batch-size 2688 --mbpo gradient_steps=8' bash studies/mbpo/pilot.sh
#
# Environment: WORK (runs and evaluations, outside the repository; default ../mbpo), NAME (the run), STEPS (40000),
# SEED (0), BUILDING (datacenter-2zone; its planner is results/model-based/BUILDING/runs/BUILDING-mpc-seedSEED),
# TARGET (--comfort-target, 99.6), FEATURES (what the policy sees beyond its sensors, default
# '--time-features --schedule-features'; a building without an IT schedule: '--time-features'), EXTRA (more
# `train` options). Progress: $WORK/progress.log; each run's log: $WORK/$NAME.log.
set -uo pipefail
cd "$(dirname "$0")/../.."
REPO=$PWD
WORK=${WORK:-$REPO/../mbpo}
NAME=${NAME:-p1}
PE=$REPO/.venv/bin/parallel-eplus
B=${BUILDING:-datacenter-2zone}
PLANNER=$REPO/results/model-based/$B/runs/$B-mpc-seed${SEED:-0}
mkdir -p "$WORK" && cd "$WORK"
echo "$(date -Is) $NAME train" >> progress.log
# shellcheck disable=SC2086  # EXTRA is a list of options
$PE train --algorithm mbpo --building "$B" --init-from "$PLANNER" --weathers CA,CO,FL --run-days 14 \
  --timesteps "${STEPS:-40000}" --comfort-target "${TARGET:-99.6}" ${FEATURES:---time-features --schedule-features} \
  --workers 2 --seed "${SEED:-0}" --run-name "$NAME" --checkpoint-every 10000 ${EXTRA:-} > "$NAME.log" 2>&1
echo "$(date -Is) $NAME evaluate (train rc=$?)" >> progress.log
$PE evaluate --building "$B" --baseline --policy "runs/$NAME/model.zip=MBPO" --weathers CA,CO,FL \
  --run-days 14 --workers 2 --out "eval-$NAME" --quiet > "eval-$NAME.log" 2>&1
echo "$(date -Is) $NAME done (evaluate rc=$?)" >> progress.log
