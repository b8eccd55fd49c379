#!/usr/bin/env bash
# The committed planners (three seeds per building) over full years on all five weathers (IL and VA held out), with
# the weather file as a perfect forecast and with BOPTEST's forecast errors; each (building, forecast, seed) is one
# `evaluate` of its own, so the study resumes where it stopped (a finished one has its results.csv; an unfinished
# one keeps its finished episodes: `evaluate --resume`).
#
#   bash studies/planner-year/run.sh [BUILDING[:FORECAST]...]   # default: every building, perfect then medium
#   bash studies/planner-year/run.sh merge                       # the seeds' tables into results/model-based/*/
#
# Environment: SEEDS (default "0 1 2"), WORK (episodes, outside the repository; default ../planner-year), SETTINGS (extra --planner
# settings, default none: the planners' own), WORKERS (2: Ray tasks, one planner and one EnergyPlus each), COMMIT
# (the code the study runs, a `git archive` copy, so later edits to the working tree cannot change its figures),
# BUILDING (the spec the planners were trained on, where it is not the target's name: a variant's planners, e.g.
# `BUILDING=results/model-based/office-small-cost/spec.toml run.sh office-small-cost:perfect` plays the runs in
# results/model-based/office-small-cost/runs/, trained on that spec).
set -euo pipefail
cd "$(dirname "$0")/../.."
REPO=$PWD
WORK=${WORK:-$REPO/../planner-year}
COMMIT=${COMMIT:-$(git rev-parse --short HEAD)}
CODE=$WORK/code-$COMMIT
[ -d "$CODE" ] || { mkdir -p "$CODE" && git archive "$COMMIT" parallel_eplus idf | tar -x -C "$CODE"; }
export PYTHONPATH=$CODE
export RAY_worker_niceness=0  # Ray runs its workers at nice 15: on a machine doing other work they starved
WORKERS=${WORKERS:-2}
PY=$REPO/.venv/bin/python
RUNS=$REPO/results/model-based

days() { case $1 in datacenter-crac) echo 351 ;; *) echo 365 ;; esac; }  # the CRAC's model fails in CO's December

one() {  # building forecast seed
    local b=$1 f=$2 s=$3 run="$RUNS/$1/runs/$1-mpc-seed$3"
    local planner=$run/planner out="$WORK/$b/$f/seed$s"
    [ -d "$run/best/planner" ] && planner=$run/best/planner  # the one --eval-every chose on CA-CO-FL's January
    [ -f "$out/results.csv" ] && { echo "$b $f seed $s: done"; return; }
    echo "$(date -Is) $b $f seed $s (code $COMMIT)"
    # from $WORK: `python -m` puts the working directory first on the path, before PYTHONPATH's copy
    (cd "$WORK" && "$PY" -m parallel_eplus.cli evaluate --building "${BUILDING:-$b}" --baseline --policy "$planner=Planner" \
        --planner "forecast=$f${SETTINGS:+,$SETTINGS}" --weathers CA,CO,FL,IL,VA --run-days "$(days "$b")" \
        --workers "$WORKERS" --backend ray --out "$out" --resume --quiet) >> "$out.log" 2>&1 || echo "failed: $out.log"
}

if [ "${1:-}" = merge ]; then
    "$PY" studies/planner-year/merge.py "$WORK" "$RUNS"
    exit 0
fi
targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=(datacenter-2zone:perfect datacenter-crac:perfect office-small:perfect
                                     datacenter-2zone:medium datacenter-crac:medium office-small:medium)
for t in "${targets[@]}"; do
    b=${t%%:*}; f=perfect; [[ $t == *:* ]] && f=${t##*:}
    mkdir -p "$WORK/$b/$f"
    for s in ${SEEDS:-0 1 2}; do one "$b" "$f" "$s"; done
done
