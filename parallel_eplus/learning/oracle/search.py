"""The oracle as an evaluation controller: at each decision, candidate sequences played in forks of the running
episode, scored with the learned planner's cost, the best one's first interval applied.

A candidate is a target action per control step over the horizon (a day); the actions it plays move toward each
target by at most `max_increment` a control step (the learned planner's limit,
planner.py's `_follow`), within [-1, 1]. Each decision plays, up to `candidates` in all:
- the warm start (the last decision's best, one interval on), the last action held, the episode's initial action
  held (the spec's, a safe anchor), then, played in closed loop in a fork of their own: the building's rule where
  it has one that sets every action (as `evaluate --rbc` plays it, twice: started fresh, and in the state of a copy
  of it stepped on every observation of the episode, which continues the rule where the oracle followed it), and
  its own
  thermostat schedules where every action is a thermostat with one (`OwnSchedules`), each followed by halfway from
  the warm start to what it did (the closed-loop candidates are the one exception to `max_increment`);
- with `offsets`, the rest of the budget on the first of those rules with a constant offset added to its actions,
  each candidate played in closed loop (a residual on the rule, searched as below: each action's offset up and
  down, random directions, the step halved after a round that finds nothing better);
- then moves from the best so far: each action's targets raised and lowered by `step` (normalized units), and as
  many moves of that length in random directions (comfort is often a thin valley across the actions: the data
  center's flow and supply temperature), over the whole horizon (even rounds) or one interval only (odd rounds:
  the first for half the moves, any for the rest; a pre-cooling, a setback ending early, an answer to a load's
  step); a round that finds nothing better halves the step. A round larger than what is left of the budget plays
  a random part of it.
The cost of a played step is `Planner._add_step_cost`'s with one member, from what the fork observed: its energy
under the building's objective times the reward's `power_weight`, and the comfort term (the K beyond each zone's
bounds, widened by the spec's tolerance and shrunk by `margin`, where the band applies, times `comfort_weight` /
margin / zones). Demand charges are not priced. The episode's own process is never stepped by a fork: it waits
at its awaited action while the forks play, then takes the chosen one (engine/eplus_side/branch.py).
"""

from __future__ import annotations

import copy
import hashlib
import json
import logging
import time
from pathlib import Path

import numpy as np

from parallel_eplus.engine.actions import scale_action
from parallel_eplus.engine.episodes.branch import Branches, frame_width
from parallel_eplus.learning.model_based.runtime.planner import Planner, PlannerSettings
from parallel_eplus.learning.oracle.settings import OracleSettings

log = logging.getLogger(__name__)
STATS_FILE = "oracle.json"  # in the episode's directory: the search's settings and its cost per decision


def ramp(last: np.ndarray, targets: np.ndarray, max_increment: float) -> np.ndarray:
    """[N, T, A] actions moving from `last` [A] toward each step's target `targets` [N, T, A] by at most
    `max_increment` a step, within [-1, 1] (planner.py's `_follow`, for the oracle's candidates)."""
    path = np.empty_like(targets)
    x = np.broadcast_to(np.asarray(last, targets.dtype), targets[:, 0].shape)
    for t in range(targets.shape[1]):
        x = np.clip(x + np.clip(targets[:, t] - x, -max_increment, max_increment), -1.0, 1.0)
        path[:, t] = x
    return path


class PlanCost:
    """What the oracle minimizes over a candidate's steps, and what it is measured by: the learned planner's cost
    (`Planner._add_step_cost`) with one member, from observed steps. `comfort`: the building's, under the run's
    objective; `power_weight`: the reward's."""

    def __init__(self, comfort, settings: OracleSettings, power_weight: float, horizon: int = 1):
        self.comfort, self.s, self.k = comfort, settings, len(comfort.temperatures)
        ps = PlannerSettings(horizon=horizon, candidates=settings.candidates, iterations=1, elites=1,
                             max_increment=settings.max_increment, init_std=settings.step, disagreement_weight=0.0,
                             terminal_weight=settings.terminal_weight)  # fmt: skip
        self.planner = Planner(None, 1, self.k, ps, settings.margin, power_weight)

    def __call__(self, infos: list[dict]) -> float:
        """The cost of observed steps (`infos`: each step's sensors by name and its `time`): the objective's energy
        times `power_weight`, and the comfort term where the band applies."""
        c, k, t = self.comfort, self.k, len(infos)
        out = np.zeros((1, t, k + 1), np.float32)
        temps = np.array([[i[z] for z in c.temperatures] for i in infos], np.float32)[None]
        out[0, :, k] = [c.energy_w(i) for i in infos]
        tol, m = c.tolerance, self.s.margin
        bounds = np.array([c.bounds(i) for i in infos], np.float32)  # [T, K, 2]
        lo, hi = bounds[..., 0] - tol + m, bounds[..., 1] + tol - m
        applies = np.array([c.always or c.applies(i["time"], i) for i in infos], np.float32)
        applied = applies * (self.s.comfort_weight / m / k)
        cost = np.zeros(t, np.float32)
        self.planner._add_step_cost(cost, out, temps, lo, hi, applied, last=False, weights=None,
                                    reference_every=None)  # fmt: skip
        if self.s.terminal_weight:  # the last step's comfort again, terminal_weight times
            end = np.zeros(1, np.float32)
            self.planner._add_step_cost(end, np.zeros((1, 1, k + 1), np.float32), temps[:, -1:], lo[-1:], hi[-1:],
                                        applied[-1:] * self.s.terminal_weight, last=False, weights=None,
                                        reference_every=None)  # fmt: skip
            cost[-1] += end[0]
        return float(cost.sum())


class OracleActor:
    """(observation, info) -> normalized action, for one episode of `evaluate --oracle`. `bind(sim)` gives it the
    episode's Simulation (run with `SimulationConfig.branching`) before its first step."""

    def __init__(self, settings: OracleSettings):
        self.s = settings
        self.sim = None
        self.rules: list = []  # played in closed loop at each decision: the building's rule, its own schedules
        self.shadow = None
        self.plan: np.ndarray | None = None  # the chosen path's actions for the rest of the interval [T, A]
        self.targets: np.ndarray | None = None  # the chosen candidate's targets per step [H, A] (the warm start)
        self.calls = 0
        self.decisions: list[dict] = []

    def bind(self, sim) -> None:
        self.sim = sim
        b, s = sim.building, self.s
        self.step_minutes = 24 * 60 / b.steps_per_day
        per = s.interval_min / self.step_minutes
        if per < 1 or abs(per - round(per)) > 1e-9:
            raise ValueError(f"--oracle interval_min={s.interval_min}: a whole number of control steps "
                             f"({self.step_minutes:g} min each)")  # fmt: skip
        self.per = int(round(per))
        self.blocks = max(1, int(round(s.horizon_h * 60 / s.interval_min)))
        self.cost_of = PlanCost(sim.setup.comfort, s, sim.config.reward.power_weight, self.blocks * self.per)
        self.last = self.initial = _unit(sim)
        self.offset = np.zeros(len(self.last))  # the first rule's best offset at the last decision (`_offsets`)
        self.warmup_steps = max(0, sim.config.warmup_days - 1) * b.steps_per_day
        rule = _rule(b)
        self.rules = [r for r in (rule, OwnSchedules.of(b)) if r is not None]
        # the building's rule stepped on every observation of the episode: played from its state, it continues the
        # rule where the oracle has been following it (a fresh one restarts its integral at each decision)
        self.shadow = copy.deepcopy(rule)

    # -- acting --------------------------------------------------------------------------------
    def __call__(self, obs: np.ndarray, info: dict) -> np.ndarray:
        if self.sim is None:
            raise RuntimeError("the oracle acts only in an episode it is bound to (evaluate --oracle)")
        if self.calls % self.per == 0:
            self.plan = self._decide(obs, info)
        if self.shadow is not None:
            self.shadow(obs, info)  # after the decision: its copies there take this observation themselves
        action = self.plan[self.calls % self.per]
        self.calls += 1
        self.last = action
        return action

    def _decide(self, obs: np.ndarray, info: dict) -> np.ndarray:
        t0 = time.perf_counter()
        s, a, h, per = self.s, len(self.last), self.blocks * self.per, self.per
        n = s.warmup_candidates if self.calls < self.warmup_steps else s.candidates
        seed = int.from_bytes(hashlib.blake2b(f"{s.seed}|{info['time'].isoformat()}".encode(),
                                              digest_size=8).digest(), "little")  # fmt: skip
        rng = np.random.default_rng(seed)
        # candidates are per-step targets [H, A], played as `ramp` makes them
        hold = np.broadcast_to(self.last, (h, a))
        warm = hold if self.targets is None else np.concatenate([self.targets[per:], np.repeat(self.targets[-1:], per,
                                                                                                0)])  # fmt: skip
        pool = [warm, hold, np.broadcast_to(self.initial, (h, a))]  # the initial action: a known-safe anchor
        best = self._play(pool[:n])
        hold_cost = best["costs"][1] if n > 1 else None
        used = min(n, len(pool))
        for rule in [*self.rules[:1], *([self.shadow] if self.shadow is not None else []), *self.rules[1:]]:
            # each in closed loop from here, then halfway to what it did
            if used >= n:
                break
            followed = self._follow_rule(rule, obs, info, h)
            used += 1
            if followed is not None:
                if followed["cost"] < best["cost"]:
                    best = followed | {"costs": best["costs"]}
                if used < n:
                    best = self._play([(warm + followed["targets"]) / 2], best)
                    used += 1
        if s.offsets and self.rules and used < n:  # the first rule's actions offset, in closed loop: the rest
            best, used = self._offsets(obs, info, h, best, used, n, rng)
        step, rounds = s.step, 0
        while used < n:
            moves = []

            def span(whole: bool = rounds % 2 == 0) -> slice:  # the whole horizon, else one interval: first or any
                if whole:
                    return slice(None)
                i = 0 if rng.random() < 0.5 else int(rng.integers(self.blocks))
                return slice(i * per, (i + 1) * per)

            for d in rng.permutation(a):  # each action up and down
                for sign in (1.0, -1.0):
                    t = best["targets"].copy()
                    t[span(), d] += sign * step
                    moves.append(np.clip(t, -1.0, 1.0))
            for _ in range(a):  # and random directions: comfort is often a thin valley across the actions
                t = best["targets"].copy()
                direction = rng.standard_normal(a)
                t[span()] += step * direction / np.linalg.norm(direction)
                moves.append(np.clip(t, -1.0, 1.0))
            moves = [moves[i] for i in rng.permutation(len(moves))] if len(moves) > n - used else moves
            moves = moves[: n - used]
            played = self._play(moves, best)
            used += len(moves)
            if played is best:  # nothing better: a finer step
                step /= 2
            best, rounds = played, rounds + 1
        self.targets = best["targets"] if best["path"] is not None else None
        ms = 1000 * (time.perf_counter() - t0)
        self.decisions.append({"time": info["time"].isoformat(), "candidates": used, "ms": round(ms, 1),
                               "cost": float(best["cost"]), "hold_cost": hold_cost,
                               "followed": best.get("rule"), "offset": best.get("offset")})  # fmt: skip
        self._write_stats()  # every decision: the episode's end is not the actor's to see
        if best["path"] is None:  # every fork failed: hold the last action
            log.warning("every candidate of the decision at %s failed; the last action is held", info["time"])
            return np.broadcast_to(self.last, (per, a)).copy()
        return best["path"][:per]

    def _offsets(self, obs, info, h: int, best: dict, used: int, n: int, rng) -> tuple[dict, int]:
        """Search the offset added to every action the first rule sets, played in closed loop (a residual on the rule,
        each candidate a followed fork): the last decision's offset, then each action's offset up and down by `step`
        and as many random directions, the step halved after a round that finds nothing better."""
        rule, a = self.rules[0], len(self.last)
        trials = [self.offset] if np.any(self.offset) else []
        step = self.s.step
        centre = self.offset
        while used < n:
            if not trials:
                trials = [centre + sign * step * np.eye(a)[d] for d in rng.permutation(a) for sign in (1.0, -1.0)]
                trials += [centre + step * v / np.linalg.norm(v) for v in rng.standard_normal((a, a))]
                trials = [trials[i] for i in rng.permutation(len(trials))][: n - used]
                improved = False
            else:
                improved = True  # the warm offset: not a round of its own
            for delta in trials:
                followed = self._follow_rule(rule, obs, info, h, np.clip(delta, -1, 1))
                used += 1
                if followed is not None and followed["cost"] < best["cost"]:
                    best, centre, improved = followed | {"costs": best["costs"]}, np.clip(delta, -1, 1), True
            trials = []
            if not improved:
                step /= 2
        self.offset = centre if best.get("offset") is not None else np.zeros(a)
        return best, used

    def _follow_rule(self, template, obs: np.ndarray, info: dict, steps: int,
                     offset: np.ndarray | None = None) -> dict | None:  # fmt: skip
        """A rule (a copy of `template`) played in closed loop in a fork over the horizon from the observation now
        (`obs`, `info`), as `evaluate --rbc` plays it, its steps not limited by `max_increment` (rate-limited, its
        integral winds up and overshoots); with `offset`, added to each of its actions: its actions as a candidate,
        with their cost."""
        sim, rule = self.sim, copy.deepcopy(template)
        shift = np.zeros(len(sim.low)) if offset is None else offset
        ruled = np.asarray(rule(obs, info), float) + shift
        if ruled.shape != (len(sim.low),) or not np.all(np.isfinite(ruled)):
            return None
        forecaster = getattr(sim, "_forecaster", None)

        def policy(values: np.ndarray) -> list[float]:
            obs, info, _ = sim.observer(values, sim.weather, forecaster)
            return scale_action(np.clip(rule(obs, info) + shift, -1, 1), sim.low, sim.high, sim.action_names)

        first = scale_action(np.clip(ruled, -1, 1), sim.low, sim.high, sim.action_names)
        branches = Branches(sim.process.pipes.dir, frame_width(len(sim.sensor_names)), sim.running, 1)
        try:
            played = branches.follow(first, policy, steps)
        finally:
            branches.close()
        if played is None or not len(played[0]):
            return None
        rows, physical = played
        lo, hi = np.asarray(sim.low, float), np.asarray(sim.high, float)
        path = (2 * (physical - lo) / (hi - lo) - 1).astype(np.float32)
        if len(path) < steps:  # the run period ended first
            path = np.concatenate([path, np.repeat(path[-1:], steps - len(path), 0)])
        return {
            "targets": path,
            "path": path,
            "cost": self._cost(rows),
            "rule": type(template).__name__,
            "offset": None if offset is None else offset.round(4).tolist(),
        }

    def _play(self, pool: list[np.ndarray], best: dict | None = None) -> dict:
        """Play candidate targets [H, A] each; the best of them and `best` (targets, path, cost, costs)."""
        targets = np.stack(pool).astype(np.float32)
        paths = ramp(self.last, targets, self.s.max_increment)
        costs = self._costs(paths)
        k = int(np.argmin(costs))
        if best is not None and not costs[k] < best["cost"]:
            return best
        path = paths[k] if np.isfinite(costs[k]) else None
        return {"targets": targets[k], "path": path, "cost": float(costs[k]), "costs": costs.tolist()}

    def _costs(self, paths: np.ndarray) -> np.ndarray:
        """Each candidate's cost over the horizon [N] from its actions [N, T, A] (normalized), played in forks."""
        sim = self.sim
        physical = [np.array([scale_action(row, sim.low, sim.high, sim.action_names) for row in p]) for p in paths]
        width = frame_width(len(sim.sensor_names))
        branches = Branches(sim.process.pipes.dir, width, sim.running, self.s.parallel)
        try:
            played = branches.run(physical)
        finally:
            branches.close()
        return np.array([np.inf if rows is None or not len(rows) else self._cost(rows) for rows in played])

    def _cost(self, rows: np.ndarray) -> float:
        """The learned planner's cost of the steps a fork played (its observation frames)."""
        sim = self.sim
        return self.cost_of([sim.observer(r, sim.weather, None)[1] for r in rows])

    def _write_stats(self) -> None:
        folder = getattr(self.sim, "episode_dir", None)
        if folder is None:
            return
        ms = [d["ms"] for d in self.decisions]
        stats = {"settings": self.s.__dict__, "decisions": len(ms), "ms_per_decision_mean": float(np.mean(ms)),
                 "candidates_per_decision_mean": float(np.mean([d["candidates"] for d in self.decisions])),
                 "per_decision": self.decisions}  # fmt: skip
        (Path(folder) / STATS_FILE).write_text(json.dumps(stats, indent=1))


class OwnSchedules:
    """The building's own controls as a rule, where every action is a thermostat setpoint with a schedule of its
    own observed (`Building.own`): each action at its schedule's value at the last observation (a step late where a
    schedule changes)."""

    def __init__(self, names: list[str], low: np.ndarray, high: np.ndarray):
        self.names, self.low, self.high = names, low, high

    @classmethod
    def of(cls, building) -> OwnSchedules | None:
        own = building.own if building.named else ()
        if len(own) != len(building.actions) or not all(o and o[0] and len(set(o)) == 1 for o in own):
            return None
        if not all(o[0] in building.sensor_names for o in own):
            return None
        low = np.array([a.low for a in building.actions], float)
        high = np.array([a.high for a in building.actions], float)
        return cls([o[0] for o in own], low, high)

    def __call__(self, obs: np.ndarray, info: dict) -> np.ndarray:
        value = np.clip([info[n] for n in self.names], self.low, self.high)
        return (2 * (value - self.low) / (self.high - self.low) - 1).astype(np.float32)


def _rule(building):
    """The building's rule as a candidate's source (None where it has none, or its actions are not plain actions: a
    rule that corrects the own schedules or releases actuators)."""
    from parallel_eplus.evaluation.controllers import RBC_LABEL, Controller

    named = building if building.named else None
    c = Controller(RBC_LABEL, "rbc")
    try:
        if named is not None and not building.spec.controller:
            return None
        if c.relinquishes(named) or c.residual(named)[0]:
            return None
        return c.make(named)
    except (ValueError, TypeError, ImportError) as e:
        log.info("the oracle searches without the building's rule (%s)", e)
        return None


def _unit(sim) -> np.ndarray:
    """The episode's initial action in normalized units (what it holds until the first decision)."""
    lo, hi = np.asarray(sim.low, float), np.asarray(sim.high, float)
    return (2 * (np.asarray(sim.initial_action, float) - lo) / (hi - lo) - 1).astype(np.float32)
