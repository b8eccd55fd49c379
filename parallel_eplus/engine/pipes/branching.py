"""The wire of a branching episode (issue 89, the oracle), which both sides name: its FIFOs beside the episode's act
pipe, and what each branch leaves in its directory (engine/eplus_side/branch.py, engine/episodes/branch.py)."""

REQUESTS = "branch-requests"  # env -> EnergyPlus: a JSON line per fork, {"id", "dir", "actions"}
ANSWERS = "branch-answers"  # EnergyPlus -> env: `pid ID PID` per fork, `done PID CODE` per child reaped
ROWS = "rows.f8"  # a branch's observation frames, float64, one row per control step
LOG = "energyplus.log"  # a branch's own log (its stdout and stderr)
