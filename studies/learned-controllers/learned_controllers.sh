#!/usr/bin/env bash
# Controllers learned with no hand-written controller, on every shipped building, three seeds each (issue 29):
# each run imitates the building's own controls (--init-from-baseline), then learns with comfort as a
# constraint (--comfort-target); trained on CA, CO and FL, evaluated frozen on all five weathers.
#
#   bash studies/learned-controllers/learned_controllers.sh start [BUILDING...]   # in the background: every (building, seed) run, in turn
#   bash studies/learned-controllers/learned_controllers.sh status                 # each run's steps, the newest log lines
#   bash studies/learned-controllers/learned_controllers.sh stop                   # SIGINT: the running trainer checkpoints and exits
#   bash studies/learned-controllers/learned_controllers.sh save                   # copy finished models into results/learned/ (commit)
#   bash studies/learned-controllers/learned_controllers.sh evaluate BUILDING      # the seeds against the built-in controls, 5 weathers
#   bash studies/learned-controllers/learned_controllers.sh recipe BUILDING        # print the building's recipe (train options)
#
# RECIPE=sac (issue 38's comparison): SAC with the comfort constraint instead, from scratch (no clone: its first
# SAC_STEPS/100 steps are random actions anyway), SAC_STEPS (200000) steps, runs named BUILDING-sac-seedN in
# ../learned-sac, saved beside the model-based runs (results/model-based/BUILDING/runs/), evaluated on full years into
# results/model-based/BUILDING/sac-year/.
# RECIPE=sac-clone (issue 51's question: does a clone start pull SAC into the band, where from scratch its multiplier
# sat at its cap?): the same SAC, its actor first imitating the building's own controls (--init-from-baseline); runs
# BUILDING-sacclone-seedN in ../learned-sac-clone, evaluated into results/model-based/BUILDING/sac-clone-year/.
#
# A run resumes from its newest checkpoint (every 100k steps; a new machine from the checkpoint `save` put in
# results/learned/), so `start` is safe to repeat after a session ends. Runs use a copy of the package at a fixed
# commit ($COMMIT, git archive), so later edits to the working tree cannot disturb them.
set -euo pipefail
cd "$(dirname "$0")/../.."
REPO=$PWD
COMMIT=${COMMIT:-$(git rev-parse --short HEAD)}
RECIPE=${RECIPE:-clone}
SEEDS=${SEEDS:-"0 1 2"}
NICE=${NICE:-0}
PY=$REPO/.venv/bin/python
if [ "$RECIPE" = sac ]; then
    TAG=-sac INIT="" WORK=${WORK:-$REPO/../learned-sac} SAVED=$REPO/results/model-based EVAL_OUT=sac-year
elif [ "$RECIPE" = sac-clone ]; then
    TAG=-sacclone INIT=--init-from-baseline WORK=${WORK:-$REPO/../learned-sac-clone} SAVED=$REPO/results/model-based
    EVAL_OUT=sac-clone-year
else
    TAG="" INIT=--init-from-baseline WORK=${WORK:-$REPO/../learned} SAVED=$REPO/results/learned EVAL_OUT=""
fi

# The recipe per building (chosen from pilots: results/learned/README.md). Every one imitates the building's own
# controls, then learns with comfort as a constraint; a short horizon (the actions act within hours) and a small
# exploration spread around the clone.
COMMON="--batch-size 4096 --gamma 0.95 --gae-lambda 0.9 --log-std-init -2.5"
recipe() {
    [ "${RECIPE#sac}" != "$RECIPE" ] && { sac_recipe "$1"; return; }
    case $1 in
    datacenter-2zone) echo "--batch-size 4096 --gamma 0.95 --gae-lambda 0.9 --log-std-init -2 --algorithm ppo --timesteps 1000000 --comfort-target 99.6 --time-features --schedule-features" ;;
    # The CRAC's model fails in Golden's cold snap of December 18-19 (roof surfaces past 200 C, its own controls
    # too): its episodes end on December 17 (351 days), on every weather alike.
    datacenter-crac) echo "$COMMON --timesteps 1000000 --comfort-target 99.9 --time-features --run-days 351" ;;
    office-small) echo "$COMMON --timesteps 1000000 --comfort-target 97.5" ;;
    *) echo "unknown building $1" >&2; exit 2 ;;
    esac
}
sac_recipe() {  # the same comfort targets, observations and periods as the clone recipe
    local features
    case $1 in
    datacenter-2zone) features="--comfort-target 99.6 --time-features --schedule-features" ;;
    datacenter-crac) features="--comfort-target 99.9 --time-features --run-days 351" ;;
    office-small) features="--comfort-target 97.5" ;;
    *) echo "unknown building $1" >&2; exit 2 ;;
    esac
    echo "--algorithm sac --timesteps ${SAC_STEPS:-200000} $features"
}
BUILDINGS=${BUILDINGS:-"datacenter-2zone datacenter-crac office-small"}

latest() {  # run folder [subfolder, default checkpoints]: its newest checkpoint
    find "$1/${2-checkpoints}" -maxdepth 1 -name 'model_*_steps.zip' 2>/dev/null | sort -V | tail -1
}

run_one() {  # building seed: resume or start it, to the end
    local b=$1 s=$2 name="$1$TAG-seed$2" code="$WORK/code-$COMMIT"
    local dir="$WORK/runs/$name" args=(--building "$b" --weathers CA,CO,FL --workers 2 --seed "$s" --quiet)
    local target
    target=$(recipe "$b" | grep -o -- "--timesteps [0-9]*" | cut -d" " -f2)
    if [ -f "$dir/model.zip" ] && [ "$("$PY" -c "import json,sys,zipfile; print(json.loads(zipfile.ZipFile(sys.argv[1]).read('data'))['num_timesteps'])" "$dir/model.zip")" -ge "$target" ]; then
        echo "$name: done"; return 0
    fi
    if [ ! -d "$dir" ] && [ -n "$(latest "$SAVED/$b/runs/$name/checkpoint" "")" ]; then  # a chunk from another machine
        mkdir -p "$dir/checkpoints"
        cp -r "$SAVED/$b/runs/$name/checkpoint/." "$dir/checkpoints/"
        cp "$SAVED/$b/runs/$name/config.json" "$SAVED/$b/runs/$name/episodes.csv" "$dir/" 2>/dev/null || true
    fi
    cd "$WORK"
    local cmd=("$PY" -m parallel_eplus.cli train)
    if [ -n "$(latest "$dir")" ]; then
        cmd+=(--resume "$dir" --quiet --timesteps "$target")  # a budget raised since continues the run
    else
        # shellcheck disable=SC2046
        cmd+=("${args[@]}" --run-name "$name" $INIT $(recipe "$b"))
        [ -d "$dir" ] && cmd+=(--overwrite)  # stopped before its first checkpoint: start it again
    fi
    echo "$(date -Is) $name: ${cmd[*]:2}"
    PYTHONPATH=$code nice -n "$NICE" "${cmd[@]}" || true
    cd "$REPO"
}

case "${1:-status}" in
start)
    shift || true
    [ $# -gt 0 ] && BUILDINGS="$*"
    mkdir -p "$WORK"
    code="$WORK/code-$COMMIT"
    [ -d "$code" ] || { mkdir -p "$code" && git archive "$COMMIT" parallel_eplus idf | tar -x -C "$code"; }
    export -f run_one recipe sac_recipe latest
    export WORK COMMIT PY SAVED REPO NICE COMMON RECIPE TAG INIT SAC_STEPS
    # seeds outer: every building's first seed before any second one
    nohup bash -c "for s in $SEEDS; do for b in $BUILDINGS; do run_one \$b \$s; done; done" >>"$WORK/learned.log" 2>&1 &
    echo $! >"$WORK/learned.pid"
    echo "started pid $(cat "$WORK/learned.pid") (code $COMMIT): $BUILDINGS x seeds $SEEDS; log $WORK/learned.log"
    ;;
status)
    for d in "$WORK"/runs/*/; do
        [ -d "$d" ] || continue
        steps=$(tail -1 "$d/episodes.csv" 2>/dev/null | cut -d, -f1 || true)
        echo "$(basename "$d"): $( [ -f "$d/model.zip" ] && echo finished || echo "checkpoint $(basename "$(latest "$d")")"), last episode at step ${steps:-?}"
    done
    tail -c 3000 "$WORK/learned.log" 2>/dev/null | tr '\r' '\n' | grep -av '^$' | tail -3 || true
    ;;
stop)
    # this study's runs only (other studies' run names end in -seedN too)
    pkill -INT -f "parallel_eplus.cli train.*(--run-name |/runs/)(${BUILDINGS// /|})$TAG-seed[0-9]" &&
        echo "asked the trainer to checkpoint and stop"
    kill "$(cat "$WORK/learned.pid")" 2>/dev/null || true
    ;;
save)
    for d in "$WORK"/runs/*/; do
        name=$(basename "$d"); b=${name%"$TAG"-seed*}; out="$SAVED/$b/runs/$name"
        mkdir -p "$out"
        cp "$d/config.json" "$d/episodes.csv" "$out/" 2>/dev/null || true
        cp "$d/imitation.json" "$out/" 2>/dev/null || true
        [ -d "$d/cloned" ] && mkdir -p "$out/cloned" && cp "$d/cloned/model.zip" "$d/cloned/vecnormalize.npz" "$d/cloned/config.json" "$out/cloned/"
        if [ -f "$d/model.zip" ]; then
            cp "$d/model.zip" "$d/vecnormalize.npz" "$out/" && rm -rf "$out/checkpoint"
        elif ckpt=$(latest "$d") && [ -n "$ckpt" ]; then  # a chunk: the next machine resumes from it
            steps=$(basename "$ckpt" | cut -d_ -f2)
            rm -rf "$out/checkpoint" && mkdir -p "$out/checkpoint"
            cp "$ckpt" "$d/checkpoints/model_vecnormalize_${steps}_steps.npz" "$out/checkpoint/"
        fi
        echo "saved $name"
    done
    ;;
evaluate)
    b=$2; policies=()
    for run in "$SAVED/$b"/runs/"$b$TAG"-seed*/; do
        [ -f "$run/model.zip" ] && policies+=(--policy "$run/model.zip=Learned")
    done
    clone="$SAVED/$b/runs/$b-seed0/cloned/model.zip"  # how close imitation alone gets (one seed: it is a fit)
    [ -f "$clone" ] && [ -z "$TAG" ] && policies+=(--policy "$clone=Cloned (before RL)")
    days=$(recipe "$b" | grep -o -- "--run-days [0-9]*" || true)  # the period trained on (default: the year)
    # shellcheck disable=SC2086
    "$REPO/.venv/bin/parallel-eplus" evaluate --building "$b" --baseline "${policies[@]}" --weathers CA,CO,FL,IL,VA \
        --workers 2 --out "$SAVED/$b/$EVAL_OUT" --quiet $days
    ;;
recipe)  # the recipe's options, for other studies of it (studies/weather/weather_study.sh)
    recipe "$2"
    ;;
*) echo "usage: $0 start|status|stop|save|evaluate BUILDING|recipe BUILDING" >&2; exit 2 ;;
esac
