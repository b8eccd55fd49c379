#!/usr/bin/env bash
# Issue 52, part 3: the small office under the example tariff (BOPTEST's dynamic energy prices, PG&E E-20's demand
# charges: parallel_eplus/buildings/tariffs/commercial-tou-demand.toml, the spec's `[kpis] tariff`). Goal: a lower
# annual electricity bill at no more occupied discomfort (K.h) than its own controls, >= 10 %, three seeds, full
# years. The learner: the planner with the bill as its objective (`--objective cost`: energy at each step's price,
# demand charges against the month's running peaks), on the prototypes' `hedged` recipe (docs/model-based.md).
#
#   bash studies/office-cost/run.sh train   # three planners, ~17 min each on 2 cores; a finished seed is skipped
#   bash studies/office-cost/run.sh save    # each finished run's planner into results/model-based/office-small-cost/runs/
#   bash studies/office-cost/run.sh year    # their full years on the five weathers (studies/planner-year, resumable)
#   bash studies/office-cost/run.sh merge   # -> results/model-based/office-small-cost/year-planner/
#
# Environment: SEEDS ("0 1 2"), WORK (runs, outside the repository; default ../office-cost), COMMIT (the code the
# training runs: a `git archive` copy).
set -euo pipefail
cd "$(dirname "$0")/../.."
REPO=$PWD
WORK=${WORK:-$REPO/../office-cost}
COMMIT=${COMMIT:-$(git rev-parse --short HEAD)}
CODE=$WORK/code-$COMMIT
PY=$REPO/.venv/bin/python
NAME=office-small-cost
SAVED=$REPO/results/model-based/$NAME/runs
MPC=max_increment=2.0,horizon=12,distill=false,comfort_hours=occupied,comfort_reference=own,comfort_level=own,own_radius=0.2,min_saving=0.03

train() {  # seed
    local run=$NAME-mpc-seed$1
    if grep -qs '"state": "finished"' "$WORK/runs/$run/status.json"; then echo "$run: finished"; return; fi
    echo "$(date -Is) $run (code $COMMIT)"
    (cd "$WORK" && PYTHONPATH=$CODE "$PY" -m parallel_eplus.cli train --building office-small --weathers CA,CO,FL \
        --workers 2 --seed "$1" --timesteps 35000 --run-name "$run" --run-days 14 \
        --random-start --comfort-margin 0.05 --algorithm mpc \
        --objective cost --time-features --comfort-target 99.8 --checkpoint-every 5000 --overwrite --mpc "$MPC") \
        > "$WORK/$run.log" 2>&1 || echo "failed: $WORK/$run.log"
}

save() {  # seed: what a year needs (the planner) and what says how it was made, not the checkpoints
    local run=$NAME-mpc-seed$1 out=$SAVED/$NAME-mpc-seed$1
    grep -qs '"state": "finished"' "$WORK/runs/$run/status.json" || { echo "$run: not finished"; return; }
    mkdir -p "$out/planner"
    cp "$WORK/runs/$run"/{config.json,status.json} "$out/"
    [ -f "$WORK/runs/$run/model_error.json" ] && cp "$WORK/runs/$run/model_error.json" "$out/"
    cp "$WORK/runs/$run/planner"/{config.json,planner.pt} "$out/planner/"
    echo "$run -> $out"
}

case ${1:-} in
    train)
        mkdir -p "$WORK"
        [ -d "$CODE" ] || { mkdir -p "$CODE" && git archive "$COMMIT" parallel_eplus idf | tar -x -C "$CODE"; }
        for s in ${SEEDS:-0 1 2}; do train "$s"; done ;;
    save) for s in ${SEEDS:-0 1 2}; do save "$s"; done ;;
    year) BUILDING=office-small bash studies/planner-year/run.sh "$NAME:perfect" ;;
    merge) bash studies/planner-year/run.sh merge ;;
    *) sed -n '2,16p' "$0"; exit 2 ;;
esac
