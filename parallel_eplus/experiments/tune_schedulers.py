"""Ray Tune's trial schedulers for a sweep's `[scheduler]`, and how many trials run at once.

ASHA (asynchronous successive halving) stops a trial whose score at a rung (grace_period x reduction_factor^k
env steps) is below the better 1/reduction_factor of the trials that reached it; PBT (population-based training)
replaces a trailing trial's weights by a leader's every `interval` steps and perturbs its `mutations` settings.
Both read the trials' results (tune_trial.py: `timesteps` is their clock, the metric usually `eval_score`).
A trial a scheduler stops early is "early-stopped" in the closing table, not "stopped": a re-run leaves it.
"""

from __future__ import annotations

import logging

from parallel_eplus.experiments.sweep_spec import SweepSpec

log = logging.getLogger(__name__)


def concurrency(spec: SweepSpec, cpus: int) -> int:
    """Trials at once: the cluster's cores over the most EnergyPlus workers any trial asks for."""
    workers = [int(spec.base.get("workers", cpus))] + [int(w) for w in spec.grid.get("workers", [])]
    return max(1, cpus // max(1, max(workers)))


def make_scheduler(spec: SweepSpec):
    """The spec's scheduler (logging the trials it stops before their planned steps); None without."""
    s = spec.scheduler
    if s is None:
        return None
    from ray.tune.schedulers import ASHAScheduler, PopulationBasedTraining, TrialScheduler

    planned = int(spec.base.get("timesteps", 0))

    def recording(cls):
        class Recording(cls):
            def on_trial_result(self, tune_controller, trial, result):
                decision = super().on_trial_result(tune_controller, trial, result)
                if decision == TrialScheduler.STOP and not result.get("done") and result.get("timesteps", 0) < planned:
                    log.info("%s stops trial %s at step %d (%s %.3g)", s.kind.upper(), trial, result["timesteps"],
                             s.metric, result.get(s.metric, float("nan")))  # fmt: skip
                return decision

        return Recording

    common = dict(time_attr="timesteps", metric=s.metric, mode=s.mode)
    if s.kind == "asha":
        return recording(ASHAScheduler)(max_t=max(planned, s.grace_period), grace_period=s.grace_period,
                                        reduction_factor=s.reduction_factor, **common)  # fmt: skip
    # synchronous: every trial reaches the decision step before any is compared. Asynchronous PBT compares a trial
    # with those that have reported so far; on a busy machine a small population's leader could finish before the
    # trailing trial's first report, and nobody was ever replaced (a flaky test, 2026-11-27).
    return recording(PopulationBasedTraining)(perturbation_interval=s.interval, quantile_fraction=s.quantile_fraction,
                                              hyperparam_mutations=dict(s.mutations), synch=True, **common)  # fmt: skip
