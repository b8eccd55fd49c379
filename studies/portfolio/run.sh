#!/usr/bin/env bash
# One chunk of the 16-prototype portfolio (issue 84): `parallel-eplus optimize` with its defaults (no per-building
# flag) on the 16 DOE prototypes the EnergyPlus wheel ships (RefBldg*), into results/optimize/, for at most MINUTES
# (default 100), then a Ctrl-C: `optimize` keeps every finished stage and the next chunk (this same command, in any
# session, on any machine with the committed folder) continues. Progress: results/optimize/progress.log.
# After a chunk: `git add results/optimize` (.gitignore keeps the bulk out: episodes, evaluation folders, logs).
set -euo pipefail
cd "$(dirname "$0")/../.."
minutes=${1:-100}
mapfile -t models < <(.venv/bin/python -c "
from parallel_eplus.buildings import resources
for p in sorted(resources.model_dirs()[-1].glob('RefBldg*.idf')): print(p)")
mkdir -p results/optimize
echo "$(date -Is) chunk of ${minutes} min: ${#models[@]} prototypes" >> results/optimize/progress.log
status=0
timeout -s INT -k 300 "${minutes}m" .venv/bin/parallel-eplus optimize "${models[@]}" --out results/optimize --quiet \
  >> results/optimize/progress.log 2>&1 || status=$?
echo "$(date -Is) chunk ended (exit ${status}; 124: its time was up, the next chunk continues)" >> results/optimize/progress.log
