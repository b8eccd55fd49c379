#!/usr/bin/env bash
# Plain TRPO (CA-CO-FL, the paper's settings and six observations) to the paper's budget: 300 full-year
# episodes, 10,518,528 steps (642 batches of 16,384), in chunks that resume one another across sessions.
#
#   bash studies/paper-budget/paper_budget.sh start     # in the background: resume the run to TARGET, log to $WORK/$RUN.log
#   bash studies/paper-budget/paper_budget.sh status    # steps done, rate, the newest checkpoint
#   bash studies/paper-budget/paper_budget.sh stop      # SIGINT: the trainer saves a checkpoint and exits
#   bash studies/paper-budget/paper_budget.sh save      # copy the newest checkpoint into results/ (commit it)
#
# The run uses its own copy of the package at a fixed commit ($COMMIT, extracted with git archive), so
# later changes to the working tree cannot disturb a run in progress. A new machine starts from the
# chunk committed under results/paper/models/$RUN (or, the first time, from the 1M-step paper-ca-co-fl).
#
# Done: the run reached 10,522,114 steps on 2026-11-25 (results/paper/README.md). Its committed statistics are
# now data-only (vecnormalize.npz), which the frozen commit cannot read; to run it again, set COMMIT to a
# commit at or after 0.3.0 and seed with SEED_FROM.
set -euo pipefail
cd "$(dirname "$0")/../.."
REPO=$PWD
COMMIT=${COMMIT:-e976d75}          # fair weather rotation; the code every chunk of this run uses
RUN=${RUN:-paper-ca-co-fl-10m}
SEED_FROM=${SEED_FROM:-results/paper/models/paper-ca-co-fl}
TARGET=${TARGET:-10518528}
WORK=${WORK:-$REPO/../paper-budget}
CODE=$WORK/code-$COMMIT
RUN_DIR=$WORK/runs/$RUN
SAVED=$REPO/results/paper/models/$RUN
PY=$REPO/.venv/bin/python

latest() { ls "$RUN_DIR"/checkpoints/model_*_steps.zip 2>/dev/null | sort -t_ -k2 -n | tail -1; }

seed_run() {  # the run directory, from the committed chunk if any, else from the 1M-step model
    local from=$SEED_FROM
    [ -f "$SAVED/model.zip" ] && from=$SAVED
    mkdir -p "$RUN_DIR/checkpoints"
    local steps
    steps=$("$PY" -c "import json,sys,zipfile; print(json.loads(zipfile.ZipFile(sys.argv[1]).read('data'))['num_timesteps'])" "$from/model.zip")
    cp "$from/model.zip" "$RUN_DIR/checkpoints/model_${steps}_steps.zip"
    cp "$from/vecnormalize.npz" "$RUN_DIR/checkpoints/model_vecnormalize_${steps}_steps.npz"
    cp "$from/episodes.csv" "$RUN_DIR/episodes.csv"
    "$PY" - "$from/config.json" "$RUN_DIR/config.json" "$RUN" "$WORK" <<'EOF'
import json, sys
cfg = json.load(open(sys.argv[1]))
cfg.update(run_name=sys.argv[3], runs_dir=sys.argv[4] + "/runs", tensorboard_dir=sys.argv[4] + "/tensorboard_logs",
           checkpoint_every=500_000)
json.dump(cfg, open(sys.argv[2], "w"), indent=2)
EOF
    echo "seeded $RUN_DIR from $from at step $steps"
}

case "${1:-status}" in
start)
    if [ ! -d "$CODE" ]; then
        mkdir -p "$CODE" && git -C "$REPO" archive "$COMMIT" parallel_eplus idf weather | tar -x -C "$CODE"
    fi
    [ -d "$RUN_DIR" ] || seed_run
    # From $WORK, with PYTHONPATH: the frozen package comes ahead of the editable install (and of the
    # repository, were it the working directory), for the trainer and its EnergyPlus workers.
    cd "$WORK"
    PYTHONPATH=$CODE nohup nice -n 10 "$PY" -m parallel_eplus.cli train --resume "$RUN_DIR" --timesteps "$TARGET" \
        >>"$WORK/$RUN.log" 2>&1 &
    echo $! >"$WORK/$RUN.pid"
    echo "started pid $(cat "$WORK/$RUN.pid"), code $COMMIT, log $WORK/$RUN.log"
    ;;
status)
    tail -c 2000 "$WORK/$RUN.log" | tr '\r' '\n' | grep -av '^$' | tail -3
    echo "newest checkpoint: $(latest)"
    ;;
stop)
    kill -INT "$(cat "$WORK/$RUN.pid")" && echo "asked $(cat "$WORK/$RUN.pid") to checkpoint and stop"
    ;;
save)
    ckpt=$(latest)
    steps=$(basename "$ckpt" | cut -d_ -f2)
    mkdir -p "$SAVED"
    cp "$ckpt" "$SAVED/model.zip"
    cp "$RUN_DIR/checkpoints/model_vecnormalize_${steps}_steps.npz" "$SAVED/vecnormalize.npz"
    cp "$RUN_DIR/config.json" "$RUN_DIR/episodes.csv" "$SAVED/"
    echo "saved step $steps to $SAVED"
    ;;
*) echo "usage: $0 start|status|stop|save" >&2; exit 2 ;;
esac
