#!/usr/bin/env bash
# The full suite, as CI runs it (.ci/run): two test processes on the cores (pytest-xdist; tests/conftest.py keeps each
# module's tests in one process and the tests that start a Ray one after another), then the wall-clock tests
# (`realtime`) alone. Each part names its slowest tests, so the suite's time has names. Extra arguments go to both.
set -euo pipefail
cd "$(dirname "$0")/.."
.venv/bin/python -m pytest -q -n 2 -m "not realtime" --durations=20 "$@"
status=0
.venv/bin/python -m pytest -q -m realtime --durations=5 "$@" || status=$?
# with arguments that select no wall-clock test, pytest's "no tests collected" (5) is not a failure
if [ "$status" -eq 5 ] && [ "$#" -gt 0 ]; then status=0; fi
exit "$status"
