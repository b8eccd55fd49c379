"""What one step is worth: the reward and, with comfort as a constraint, its cost, from the building's comfort object.

One place for the per-step arithmetic every learner reads through `info`: the energy the objective counts (with
demand charges, the running month's share of them, pricing/bill.py), the reward (scoring/reward.py) and the
comfort cost beside it (`--comfort-margin`).
"""

from __future__ import annotations

from parallel_eplus.buildings.scoring.reward import reward


class StepScorer:
    """Scores steps of one episode after another; `start` resets what an episode accumulates (the month's peaks)."""

    def __init__(self, comfort, reward_config, margin_c: float | None):
        self.comfort, self.reward_config, self.margin_c = comfort, reward_config, margin_c
        self._temps = comfort.temperatures
        self._demand = None  # the demand charges' surrogate of the running episode (cost objective)

    def start(self) -> None:
        self._demand = self.comfort.demand_tracker()  # the month's running peaks start at 0 each episode

    def __call__(self, info: dict) -> tuple[float, dict, bool]:
        """(reward, its parts, whether comfort applies); `info` gains the parts and the comfort cost."""
        comfort, margin = self.comfort, self.margin_c
        applies = comfort.always or comfort.applies(info["time"], info)
        temps = tuple(map(info.__getitem__, self._temps))
        energy = comfort.energy_w(info)
        if self._demand is not None:  # --objective cost with demand charges: their per-step share
            info["demand_charge"], demand_w = comfort.demand_w(self._demand, info)
            energy += demand_w
        r, parts = reward(temps, energy, self.reward_config, applies and margin is None)
        info.update(parts)
        info["comfort_applies"] = applies
        if margin is not None:  # comfort as a constraint: its cost goes to the learner beside the energy reward
            bounds = comfort.bounds(info) if comfort.per_step else None
            cost, out = comfort.cost(temps, margin, bounds) if applies else (0.0, 0)
            info.update(comfort_cost=cost, comfort_out=out, comfort_zones=len(temps) if applies else 0)
        return r, parts, applies
