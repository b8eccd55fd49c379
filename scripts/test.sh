#!/usr/bin/env bash
# The full suite, as CI runs it (.ci/run): two test processes on the cores (pytest-xdist; tests/conftest.py keeps each
# module's tests in one process and the tests that start a Ray one after another), then the wall-clock tests
# (`realtime`) alone. Each part names its slowest tests, so the suite's time has names. Extra arguments go to both.
set -euo pipefail
cd "$(dirname "$0")/.."
.venv/bin/python -m pytest -q -n 2 -m "not realtime" --durations=20 "$@"
# With no arguments, the wall-clock tests are collected from their own files only (tests/conftest.py's
# REALTIME_TESTS), not the whole suite again (12 s)
files=()
if [ "$#" -eq 0 ]; then
  mapfile -t files < <(.venv/bin/python -c 'import ast; t = ast.parse(open("tests/conftest.py").read())
names = next(n.value for n in t.body if isinstance(n, ast.Assign) and getattr(n.targets[0], "id", "") == "REALTIME_TESTS")
print(*sorted({e.value.split("::")[0] for e in names.elts}), sep="\n")')
fi
status=0
.venv/bin/python -m pytest -q -m realtime --durations=5 "${files[@]}" "$@" || status=$?
# with arguments that select no wall-clock test, pytest's "no tests collected" (5) is not a failure
if [ "$status" -eq 5 ] && [ "$#" -gt 0 ]; then status=0; fi
exit "$status"
