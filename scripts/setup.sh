#!/usr/bin/env bash
# Create .venv and install parallel-eplus with EnergyPlus 25.2 (PyPI) and the CPU build of torch: every extra (`train`:
# simulate, learn, evaluate; `serve`/`export`: deploy; `ray`, `search`; `bacnet`; `dev`: tests and linters; `docs`: the site).
set -euo pipefail
cd "$(dirname "$0")/.."
python3 -m venv .venv
# torch first, pinned: 2.13.0 resolves to the CPU wheel here; an unpinned torch pulls several GB of CUDA.
.venv/bin/pip install -q --disable-pip-version-check "torch==2.13.0"
.venv/bin/pip install -q --disable-pip-version-check -e ".[train,dev,docs,ray,search,serve,export,bacnet]"
# The EnergyPlus side of each control step in C (parallel_eplus/eplus_callback.c), compiled once here;
# without a C compiler it warns, and the Python bridge does the same work, slower.
.venv/bin/python -c "import logging; logging.basicConfig(format='%(message)s'); from parallel_eplus.engine import native; native.bridge_library()"
