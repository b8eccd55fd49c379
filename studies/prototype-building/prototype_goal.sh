#!/usr/bin/env bash
# Issue 38's last goal, taken as a new user would: a DOE prototype from the EnergyPlus wheel that no spec ships for
# (default: the stand-alone retail store), `building init` -> the starter's two "all thermostats together" actions
# uncommented -> `building check` -> `train` with the recipe for a new building (docs/training.md: the policy corrects
# the building's own thermostat schedules, comfort as a constraint in the building's own bounds, the checkpoint
# chosen by evaluation on the training weathers) on CA, CO and FL, seeds 0-2 -> `evaluate` on the five weathers
# (IL and VA held out), full years, against the building's own controls.
#
#   bash studies/prototype-building/prototype_goal.sh run         # init and check (once), each seed's run (resumed if stopped), evaluate
#   bash studies/prototype-building/prototype_goal.sh evaluate    # the runs' chosen policies against the building's own controls
#
# Settings (environment): MODEL (a model of the wheel's data/model/), STEPS (200000), SEEDS ("0 1 2"), WORK (runs;
# default ../prototype), OUT (results/model-based/prototype-NAME), EXTRA (more train options), EVAL_DAYS (default:
# the year). A tiny trial: WORK=/tmp/p OUT=/tmp/p/out STEPS=2048 SEEDS=0 EVAL_DAYS=2
# EXTRA="--run-days 2 --batch-size 1024 --eval-every 1024 --eval-days 2" bash studies/prototype-building/prototype_goal.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
REPO=$PWD
PY=$REPO/.venv/bin/python
CLI=("$PY" -m parallel_eplus.cli)
MODEL=${MODEL:-RefBldgStand-aloneRetailNew2004_Chicago.idf}
STEPS=${STEPS:-200000}
SEEDS=${SEEDS:-"0 1 2"}
WORK=${WORK:-$REPO/../prototype}
NAME=$(basename "$MODEL" .idf)
OUT=${OUT:-$REPO/results/model-based/prototype-$NAME}
SPEC=$WORK/$NAME.toml
EXTRA=${EXTRA:-}
# The recipe for a building nobody tuned: corrections of up to 0.3 of each setpoint's half-range around its own
# schedule (a zero correction is the building's own controls), small first exploration, the clock observed, comfort
# held at the built-in's level in its own bounds, the best checkpoint by a year on each training weather.
RECIPE=(--residual 0.3 --residual-space builtin --log-std-init -2.5 --time-features --batch-size 4096 --gamma 0.95
        --gae-lambda 0.9 --comfort-target 99.9 --comfort-margin 0.1 --eval-every 50000 --eval-days 365
        --target "in_band_pct>=99.9,energy_change_pct<=0")

init() {
    [ -f "$SPEC" ] && return 0
    mkdir -p "$WORK"
    local model
    model=$("$PY" -c "import sys; from parallel_eplus.buildings.resources import model_file; print(model_file(sys.argv[1]))" "$MODEL")
    "${CLI[@]}" building init "$model" -o "$SPEC.starter"
    # what the starter asks of its user: uncomment the actions the agent should own (the two written first)
    "$PY" - "$SPEC.starter" "$SPEC" <<'PYEOF'
import sys
from pathlib import Path
out, on = [], False
for line in Path(sys.argv[1]).read_text().splitlines():
    if line.startswith("# all ") and "thermostats'" in line:  # a block's heading: its lines follow, to a blank line
        on = True
    elif on and line.startswith("# "):
        line = line[2:]
    elif not line.strip():
        on = False
    out.append(line)
Path(sys.argv[2]).write_text("\n".join(out) + "\n")
PYEOF
    "${CLI[@]}" building check "$SPEC"
}

run_one() {
    local s=$1 name="$NAME-own-seed$1"
    local dir="$WORK/runs/$name"
    local cmd=("${CLI[@]}" train --quiet)
    if [ -f "$dir/model.zip" ]; then echo "$name: done"; return 0; fi
    if ls "$dir"/checkpoints/*.zip >/dev/null 2>&1; then
        cmd+=(--resume "$dir" --timesteps "$STEPS")
    else
        # shellcheck disable=SC2086
        cmd+=(--building "$SPEC" --weathers CA,CO,FL --workers 2 --seed "$s" --run-name "$name" --timesteps "$STEPS"
              "${RECIPE[@]}" $EXTRA)
        [ -d "$dir" ] && cmd+=(--overwrite)
    fi
    echo "$(date -Is) $name"
    (cd "$WORK" && "${cmd[@]}")
}

evaluate() {
    local policies=() s
    for s in $SEEDS; do
        local run="$WORK/runs/$NAME-own-seed$s"
        local chosen="$run/best/model.zip"  # the checkpoint evaluation on the training weathers chose
        [ -f "$chosen" ] || chosen="$run/model.zip"
        [ -f "$chosen" ] && policies+=(--policy "$chosen=Learned")
    done
    [ ${#policies[@]} -gt 0 ] || { echo "no finished run under $WORK/runs" >&2; exit 1; }
    # shellcheck disable=SC2046
    "${CLI[@]}" evaluate --building "$SPEC" --baseline "${policies[@]}" --weathers CA,CO,FL,IL,VA --workers 2 --quiet \
        $( [ -n "${EVAL_DAYS:-}" ] && echo "--run-days $EVAL_DAYS") --out "$OUT"
    cp "$SPEC" "$OUT/spec.toml"
    for s in $SEEDS; do  # each run's small files: config, episodes, evaluations, the chosen policy
        local run="$WORK/runs/$NAME-own-seed$s" to="$OUT/runs/$NAME-own-seed$s"
        [ -d "$run" ] || continue
        mkdir -p "$to"
        cp "$run"/{config.json,episodes.csv,evaluations.csv,target.json} "$to/" 2>/dev/null || true
        cp -r "$run/best" "$to/" 2>/dev/null || true
    done
}

case "${1:-run}" in
run)
    init
    for s in $SEEDS; do run_one "$s"; done
    evaluate
    ;;
evaluate) evaluate ;;
*) echo "usage: $0 run|evaluate" >&2; exit 2 ;;
esac
