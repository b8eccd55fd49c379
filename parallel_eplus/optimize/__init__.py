"""`parallel-eplus optimize`: a building in, a saving and a controller out (issue 84, item 2).

What a careful engineer does with a building nobody tuned, as one resumable command: prepare it (`building init` with
the starter's recommended actions, `building check`), find BOPTEST's test days once per weather, score its own
controls, the rules it supports and its preset's learned controller on the training and held-out weathers, choose by
the held-out weathers only (do no harm: the own controls unless a candidate saves at no more occupied discomfort),
export the choice and write the report. Several buildings: one folder each and a summary.

It owns the stages, their order, the budget, the folder layout and status.json, the choice and the report. Every step
that a user could run is run as that command (`python -m parallel_eplus.cli ...` in a child process, its output in a
log beside the results), so the product does exactly what the documented commands do. Beside experiments, bench and
deploy, below the command line: it may import evaluation, runs, engine, buildings, presets and io; it never imports
cli (cli/optimize.py declares the subcommand and calls `run_optimize`).
"""

from parallel_eplus.optimize.portfolio import run_optimize
from parallel_eplus.optimize.settings import OptimizeSettings

__all__ = ["OptimizeSettings", "run_optimize"]
