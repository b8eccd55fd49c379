#!/usr/bin/env bash
# Issue 52, part 3: the small office under the example tariff (BOPTEST's dynamic energy prices, PG&E E-20's demand
# charges: parallel_eplus/buildings/tariffs/commercial-tou-demand.toml, the spec's `[kpis] tariff`). Goal: a lower
# annual electricity bill at no more occupied discomfort (K.h) than its own controls, >= 10 %, three seeds, full
# years. The learner: the planner with the bill as its objective (`--objective cost`: energy at each step's price,
# demand charges against the month's running peaks), on the prototypes' `hedged` recipe (docs/model-based.md),
# on a copy of the built-in spec whose cooling setpoint reaches down to the occupied heating setpoint, 21 C (the
# built-in stops at 23: 1 K below its own 24 C leaves no room to pre-cool ahead of the afternoon's prices and peaks).
#
#   bash studies/office-cost/run.sh spec    # results/model-based/office-small-cost/spec.toml from the built-in spec
#   bash studies/office-cost/run.sh train   # three planners, ~17 min each on 2 cores; a finished seed is skipped,
#                                           # a stopped one goes on from its last checkpoint (every 5,000 steps)
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
SPEC=$REPO/results/model-based/$NAME/spec.toml
MPC=max_increment=2.0,horizon=12,distill=false,comfort_hours=occupied,comfort_reference=own,comfort_level=own,own_radius=0.2,min_saving=0.03

spec() {  # the built-in spec with the cooling setpoint's range widened down to 21 C, under its own name
    mkdir -p "$(dirname "$SPEC")"
    "$PY" - "$REPO/parallel_eplus/buildings/specs/office-small.toml" "$SPEC" <<'PY'
import re, sys
text = open(sys.argv[1]).read()
head = "# Written by studies/office-cost/run.sh from the built-in office-small spec: the cooling setpoint from 21 C.\n"
text = text.replace('name = "office-small"', 'name = "office-small-precool"', 1)
text, n = re.subn(r'(name = "cooling_setpoint_c"[^\n]*\nunit = "C"\nlow = )23\.0', r"\g<1>21.0", text)
assert n == 1, "the built-in spec's cooling setpoint block changed: update studies/office-cost/run.sh"
open(sys.argv[2], "w").write(head + text)
PY
    echo "written: $SPEC"
}

train() {  # seed
    local run=$NAME-mpc-seed$1
    if grep -qs '"state": "finished"' "$WORK/runs/$run/status.json"; then echo "$run: finished"; return; fi
    local args
    if compgen -G "$WORK/runs/$run/checkpoints/*" > /dev/null; then  # a stopped run: on from its last checkpoint
        args=(--resume "runs/$run" --timesteps 35000)
    else
        args=(--building "$SPEC" --weathers CA,CO,FL --workers 2 --seed "$1" --timesteps 35000 --run-name "$run"
              --run-days 14 --random-start --comfort-margin 0.05 --algorithm mpc --objective cost --time-features
              --comfort-target 99.8 --checkpoint-every 5000 --overwrite --mpc "$MPC")
    fi
    echo "$(date -Is) $run (code $COMMIT): ${args[0]}"
    (cd "$WORK" && PYTHONPATH=$CODE "$PY" -m parallel_eplus.cli train "${args[@]}") >> "$WORK/$run.log" 2>&1 \
        || echo "failed or stopped: $WORK/$run.log (run it again to go on from the last checkpoint)"
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
    spec) spec ;;
    train)
        [ -f "$SPEC" ] || spec
        mkdir -p "$WORK"
        [ -d "$CODE" ] || { mkdir -p "$CODE" && git archive "$COMMIT" parallel_eplus idf | tar -x -C "$CODE"; }
        for s in ${SEEDS:-0 1 2}; do train "$s"; done ;;
    save) for s in ${SEEDS:-0 1 2}; do save "$s"; done ;;
    year) BUILDING=$SPEC bash studies/planner-year/run.sh "$NAME:perfect" ;;
    merge) bash studies/planner-year/run.sh merge ;;
    *) sed -n '2,18p' "$0"; exit 2 ;;
esac
