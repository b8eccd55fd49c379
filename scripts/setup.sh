#!/usr/bin/env bash
# Create .venv and install parallel-eplus with EnergyPlus 25.2 (PyPI) and the CPU build of torch.
set -euo pipefail
cd "$(dirname "$0")/.."
python3 -m venv .venv
# torch first, pinned: 2.13.0 resolves to the CPU wheel here; an unpinned torch pulls several GB of CUDA.
.venv/bin/pip install -q --disable-pip-version-check "torch==2.13.0"
.venv/bin/pip install -q --disable-pip-version-check -e ".[dev,ray]"
