#!/usr/bin/env bash
# Issue 40's measurement: does weather noise or a forecast make the learned controller hold its comfort and savings
# on climates it never saw? Per shipped building, seeds 0-2, trained on CA, CO and FL with today's recipe
# (studies/learned-controllers/learned_controllers.sh recipe BUILDING) in four variants:
#   base      the recipe
#   noise     + --weather-noise $NOISE           (each episode a perturbed year; docs/weather.md)
#   forecast  + --forecast $FORECAST             (the outdoor temperature's next hours in the observation)
#   both      + both
# then each evaluated frozen on the five paper weathers, on noisy versions of them and on the 11 climates never
# trained or tuned on, against the building's own controls.
#
#   bash studies/weather/weather_study.sh run [CHUNK]        # every unfinished run, in turn, CHUNK more steps each (default:
#                                                   # to the end); stop any time (Ctrl-C checkpoints), run again
#   bash studies/weather/weather_study.sh status             # each run's steps
#   bash studies/weather/weather_study.sh evaluate BUILDING  # paper weathers, noisy years, unseen climates -> $OUT/BUILDING/
#                                                   # (each part skipped when its results.csv is there)
#   bash studies/weather/weather_study.sh climates BUILDING [RUNS LABEL]  # issue 29's learned controllers (or the policies
#                                                   # of RUNS/*/model.zip, into $OUT/climates-LABEL) on all 16
#                                                   # climates against the built-in controls
#   bash studies/weather/weather_study.sh table              # $OUT/README.md's tables and figures from the evaluations
#   bash studies/weather/weather_study.sh save               # each run's small files to $OUT/runs (commit them): a finished
#                                                   # run's policy, an unfinished one's newest save to resume from
#   bash studies/weather/weather_study.sh restore            # those back into $WORK/runs, on a new machine, before `run`
#
# Settings (environment): BUILDINGS, SEEDS, VARIANTS, TIMESTEPS (default: the recipe's), NOISE (default:
# Sinergym's dry bulb 1 K, 24 h), FORECAST (hours, 24), FORECAST_ERROR (BOPTEST's low/medium/high; default exact),
# NOISY_YEARS (3), EXTRA (more train options, e.g. a tiny trial: EXTRA="--run-days 2 --batch-size 512"),
# EVAL_DAYS (evaluation period; default the recipe's), WORK (runs; default ../weather-study), OUT (results/weather),
# COMMIT (the code training and `evaluate` run with: a copy of the package at that commit, $WORK/code-COMMIT, so edits
# to the working tree cannot change a study under way; default HEAD).
set -euo pipefail
cd "$(dirname "$0")/../.."
REPO=$PWD
PY=$REPO/.venv/bin/python
CLI=("$PY" -m parallel_eplus.cli)
COMMIT=${COMMIT:-$(git rev-parse --short HEAD)}
WORK=${WORK:-$REPO/../weather-study}
OUT=${OUT:-$REPO/results/weather}
BUILDINGS=${BUILDINGS:-"datacenter-2zone datacenter-crac office-small"}
SEEDS=${SEEDS:-"0 1 2"}
VARIANTS=${VARIANTS:-"base noise forecast both"}
NOISE=${NOISE:-default}
FORECAST=${FORECAST:-24}
FORECAST_ERROR=${FORECAST_ERROR:-}
NOISY_YEARS=${NOISY_YEARS:-3}
EXTRA=${EXTRA:-}
PAPER=CA,CO,FL,IL,VA
UNSEEN=$("$PY" -c "from parallel_eplus.buildings.weather.files import ALL_WEATHERS as A; print(','.join(A[5:]))")

recipe() { bash "$REPO/studies/learned-controllers/learned_controllers.sh" recipe "$1"; }
variant_options() {
    local forecast=(--forecast "$FORECAST")
    [ -n "$FORECAST_ERROR" ] && forecast+=(--forecast-error "$FORECAST_ERROR")
    case $1 in
    base) ;;
    noise) echo "--weather-noise $NOISE" ;;
    forecast) echo "${forecast[*]}" ;;
    both) echo "--weather-noise $NOISE ${forecast[*]}" ;;
    *) echo "unknown variant $1" >&2; exit 2 ;;
    esac
}
target() { echo "${TIMESTEPS:-$(recipe "$1" | grep -o -- "--timesteps [0-9]*" | cut -d" " -f2)}"; }
steps_done() {  # the run's newest save (checkpoint or chunk's end), in env steps; 0 if none
    "$PY" - "$1" <<'PYEOF'
import json, sys, zipfile
from pathlib import Path
from parallel_eplus.runs.run_files import saves_newest_first
saves = saves_newest_first(Path(sys.argv[1])) if Path(sys.argv[1]).is_dir() else []
print(json.loads(zipfile.ZipFile(saves[0]).read("data"))["num_timesteps"] if saves else 0)
PYEOF
}

run_one() {  # building seed variant chunk: the run's next chunk (or all of it)
    local b=$1 s=$2 v=$3 chunk=$4 name="$1-$3-seed$2"
    local dir="$WORK/runs/$name" goal done next
    goal=$(target "$b")
    done=$(steps_done "$dir")
    if [ "$done" -ge "$goal" ]; then echo "$name: done ($done steps)"; return 0; fi
    next=$goal
    [ -n "$chunk" ] && [ $((done + chunk)) -lt "$goal" ] && next=$((done + chunk))
    local cmd=("${CLI[@]}" train --quiet)
    if [ "$done" -gt 0 ]; then
        cmd+=(--resume "$dir" --timesteps "$next")
    else
        # shellcheck disable=SC2046
        cmd+=(--building "$b" --weathers CA,CO,FL --workers 2 --seed "$s" --run-name "$name" --init-from-baseline
              $(recipe "$b") $(variant_options "$v") $EXTRA --timesteps "$next")  # runs/ and tensorboard_logs/ in $WORK
        [ -d "$dir" ] && cmd+=(--overwrite)  # stopped before its first save: start it again
    fi
    echo "$(date -Is) $name: $done -> $next steps"
    snapshot
    (cd "$WORK" && PYTHONPATH=$WORK/code-$COMMIT "${cmd[@]}")
}

snapshot() {  # the package at $COMMIT, for training and evaluating
    local code="$WORK/code-$COMMIT"
    [ -d "$code" ] || { mkdir -p "$code" && git -C "$REPO" archive "$COMMIT" parallel_eplus idf weather | tar -x -C "$code"; }
}

policies() {  # building: --policy PATH=LABEL for every finished run of every variant
    local b=$1 v run
    for v in $VARIANTS; do
        for run in "$WORK/runs/$b-$v-seed"*/; do
            [ -f "$run/model.zip" ] && [ "$(steps_done "$run")" -ge "$(target "$b")" ] && echo "--policy $run/model.zip=$v"
        done
    done
}
eval_days() { echo "${EVAL_DAYS:+--run-days $EVAL_DAYS}$( [ -z "${EVAL_DAYS:-}" ] && recipe "$1" | grep -o -- "--run-days [0-9]*" || true)"; }

case "${1:-status}" in
run)
    mkdir -p "$WORK/runs"
    for s in $SEEDS; do for v in $VARIANTS; do for b in $BUILDINGS; do
        run_one "$b" "$s" "$v" "${2:-}"
    done; done; done
    ;;
status)
    for d in "$WORK"/runs/*/; do
        [ -d "$d" ] && echo "$(basename "$d"): $(steps_done "$d") steps"
    done
    ;;
evaluate)
    b=$2
    # shellcheck disable=SC2046
    set -- $(policies "$b")
    [ $# -gt 0 ] || { echo "no finished run of $b under $WORK/runs" >&2; exit 1; }
    common=(evaluate --building "$b" --baseline "$@" --workers 2 --quiet $(eval_days "$b"))
    snapshot  # the policies run with the code they were trained with
    export PYTHONPATH=$WORK/code-$COMMIT
    part() {  # name, options: one evaluation, skipped when its results are there (delete the folder to redo it)
        local name=$1; shift
        if [ -f "$OUT/$b/$name/results.csv" ]; then echo "$b/$name: already evaluated"; return; fi
        "${CLI[@]}" "${common[@]}" "$@" --out "$OUT/$b/$name" || true
    }
    part paper --weathers "$PAPER"
    part noisy --weathers "$PAPER" --weather-noise "$NOISE" --noisy-years "$NOISY_YEARS"
    part climates --weathers "$UNSEEN"
    ;;
climates)
    b=$2 runs=${3:-$REPO/results/learned/$2/runs} label=${4:-}; learned=()
    for run in "$runs"/*/; do
        [ -f "$run/model.zip" ] && learned+=(--policy "$run/model.zip=Learned")
    done
    [ ${#learned[@]} -gt 0 ] || { echo "no policy (*/model.zip) in $runs" >&2; exit 1; }
    # shellcheck disable=SC2046
    "${CLI[@]}" evaluate --building "$b" --baseline "${learned[@]}" --weathers all --workers 2 --quiet \
        $(eval_days "$b") --out "$OUT/climates${label:+-$label}/$b" || true
    ;;
table)
    "$PY" "$REPO/studies/weather/weather_table.py" "$OUT"
    ;;
save)
    for d in "$WORK"/runs/*/; do
        name=$(basename "$d"); out="$OUT/runs/$name"
        newest=$("$PY" -c "import sys; from pathlib import Path; from parallel_eplus.runs.run_files import \
saves_newest_first as s; n = s(Path(sys.argv[1])); print(n[0] if n else '')" "$d")
        [ -n "$newest" ] || continue
        rm -rf "$out" && mkdir -p "$out"
        cp "$d"/{config.json,status.json,episodes.csv,builtin.csv,imitation.json} "$out/" 2>/dev/null || true
        steps=$(steps_done "$d")
        if [ "$(basename "$newest")" = model.zip ]; then
            cp "$d/model.zip" "$d/vecnormalize.npz" "$out/"
        else  # unfinished: its newest checkpoint only (git keeps no modification times to order saves by)
            mkdir -p "$out/checkpoints"
            cp "$newest" "$out/checkpoints/model_${steps}_steps.zip"
            cp "$d/checkpoints/model_vecnormalize_${steps}_steps.npz" "$out/checkpoints/" 2>/dev/null || true
        fi
        echo "saved $name ($steps steps)"
    done
    ;;
restore)
    mkdir -p "$WORK/runs"
    for d in "$OUT"/runs/*/; do
        name=$(basename "$d")
        if [ -e "$WORK/runs/$name" ]; then echo "$name: already in $WORK/runs"; continue; fi
        cp -r "$d" "$WORK/runs/$name" && echo "restored $name ($(steps_done "$WORK/runs/$name") steps)"
    done
    ;;
*) echo "usage: $0 run [CHUNK]|status|evaluate BUILDING|climates BUILDING|table|save|restore" >&2; exit 2 ;;
esac
