#!/usr/bin/env bash
# Reproduce the paper's Table 1: train TRPO (CA) and TRPO (CA-CO-FL) with the paper's settings and
# full-year episodes, then evaluate the built-in controller, the rule-based controller and both
# policies on all five weathers. Results go to results/paper/.
#
#   TIMESTEPS=1000000 WORKERS=2 bash scripts/reproduce_paper.sh
set -euo pipefail
cd "$(dirname "$0")/.."
TIMESTEPS=${TIMESTEPS:-1000000}
WORKERS=${WORKERS:-$(nproc)}
PE=.venv/bin/parallel-eplus
start=$(date +%s)

$PE train --workers "$WORKERS" --weathers CA,CO,FL --timesteps "$TIMESTEPS" --run-name paper-ca-co-fl \
    ${RESUME_CCF:+--resume runs/paper-ca-co-fl}
$PE train --workers "$WORKERS" --weathers CA --timesteps "$TIMESTEPS" --run-name paper-ca \
    ${RESUME_CA:+--resume runs/paper-ca}

mkdir -p results/paper/models
for run in paper-ca paper-ca-co-fl; do
    mkdir -p "results/paper/models/$run"
    cp "runs/$run/model.zip" "runs/$run/vecnormalize.npz" "runs/$run/config.json" "runs/$run/episodes.csv" \
        "results/paper/models/$run/"
    $PE plot "runs/$run" && cp "runs/$run/convergence.png" "results/paper/convergence-$run.png"
done

$PE evaluate --baseline --rbc \
    --policy "results/paper/models/paper-ca/model.zip=TRPO (CA)" \
    --policy "results/paper/models/paper-ca-co-fl/model.zip=TRPO (CA-CO-FL)" \
    --weathers CA,CO,FL,IL,VA --run-days 365 --workers "$WORKERS" \
    --histogram "TRPO (CA-CO-FL),VA" --out results/paper

echo "reproduction took $(( ($(date +%s) - start) / 60 )) minutes"
