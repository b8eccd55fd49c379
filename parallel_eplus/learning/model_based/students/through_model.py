"""A policy network learned through the planner's model: the planner's cost over its horizon, differentiated through
the ensemble (SVG(H), Heess et al. 2015), not the planner's actions copied (distill.py).

From real states (`Starts`: what the policy saw in EnergyPlus, the action before it, the time and the weather),
every member of the ensemble rolls its own trajectory over the planner's horizon (as the planner's, PETS's TS-inf),
the policy acting at each step on the observation rebuilt from the member's predicted state: the zone temperatures
and energy parts the model predicts, the outdoor dry bulb from the weather file, the time and IT-schedule features
from the clock, any other sensor held at its start. Each step costs what the planner's does (planner.py): energy
x power_weight, the comfort surrogate beyond the bounds shrunk by the margin where they apply, and the members'
spread; an action outside the data's support or a step beyond the planner's `max_increment` pays too, since the
model was never shown either. The policy is an SB3 actor-critic's (its observation normalizer fixed), so `export`
and `serve` take it as any policy.
"""

from __future__ import annotations

import contextlib
import dataclasses
import datetime as dt
from dataclasses import dataclass
from typing import TYPE_CHECKING

import gymnasium as gym
import numpy as np
import torch as th

from parallel_eplus.buildings.clock import schedule_features, time_features
from parallel_eplus.learning.model_based.model.dataset import next_state
from parallel_eplus.learning.model_based.model.exogenous import model_schedule
from parallel_eplus.learning.model_based.runtime.features import step_times
from parallel_eplus.runs.norm_stats import NormStats

if TYPE_CHECKING:
    from parallel_eplus.learning.model_based.control.mpc import MPC

OUTDOOR = "site outdoor air drybulb temperature"


@dataclass(frozen=True)
class Clock:
    """The features the env appends to the sensors from the clock (engine/observation.py): time of day and week,
    and the IT-load schedule's, as the run observes them; a rollout computes them for each coming step."""

    time: bool = False
    schedule: tuple[tuple[float, float], ...] | None = None

    def __call__(self, t: dt.datetime) -> list[float]:
        schedule = schedule_features(t, self.schedule) if self.schedule else ()
        return [*(time_features(t) if self.time else ()), *schedule]

    @property
    def width(self) -> int:
        return len(self(dt.datetime(2013, 1, 7)))


class Starts:
    """Real states the rollouts branch from: observation, the action before it (normalized), time and weather."""

    def __init__(self):
        self.obs, self.prev, self.times, self.weathers = [], [], [], []

    @classmethod
    def of(cls, obs, prev, times, weathers) -> Starts:
        starts = cls()
        starts.obs, starts.prev = list(np.asarray(obs, np.float32)), list(np.asarray(prev, np.float32))
        starts.times, starts.weathers = list(times), list(weathers)
        return starts

    def add(self, obs, prev, when, weather) -> None:
        self.obs.append(np.asarray(obs, np.float32))
        self.prev.append(np.asarray(prev, np.float32))
        self.times.append(when)
        self.weathers.append(weather)

    def __len__(self) -> int:
        return len(self.obs)


class Rollouts:
    """The policy's cost over the planner's horizon through the ensemble, differentiable in the policy's weights."""

    def __init__(self, mpc: MPC, building, stats, policy, clock: Clock | None = None, margin_c: float | None = None,
                 move_weight: float = 10.0):  # fmt: skip
        self.mpc, self.layout, self.s, self.clock = mpc, mpc.layout, mpc.settings, clock or Clock()
        self.margin_c, self.move_weight = margin_c or mpc.margin_c, move_weight
        self.model, self.policy = mpc.model, policy
        self.mean = th.as_tensor(stats.obs_mean, dtype=th.float32)
        self.scale = th.as_tensor(np.sqrt(stats.obs_var + stats.epsilon), dtype=th.float32)
        self.clip = float(stats.clip_obs)
        self.low, self.high = (th.as_tensor(b) for b in mpc.support)
        sensors = list(self.layout.sensors)
        names = self.layout.state_names
        self.temp_at = [sensors.index(n) for n in self.layout.temperatures]
        self.hvac_at = [sensors.index(n) for n in self.layout.hvac]
        self.total_at = [sensors.index(n) for n in self.layout.energy][:1]
        self.outdoor_at = [i for i, o in enumerate(building.observed) if o.variable.lower() == OUTDOOR]
        self.n_sensors = len(sensors)
        self.k = len(self.layout.temperatures)
        if names[self.k :] != (("non_hvac_w", *self.layout.hvac) if self.layout.hvac else self.layout.energy):
            raise ValueError(f"the model's state {names} is not the layout's temperatures and energy parts")

    def batch(self, starts: Starts, rows: np.ndarray) -> dict:
        """The rows' inputs over the horizon: observation, previous action, exogenous inputs, outdoor dry bulb,
        whether the band applies and the bounds at each step's end."""
        h, mpc = self.s.horizon, self.mpc
        exo, outdoor, applies, bounds, clock, weights = [], [], [], [], [], []
        for r in rows:
            times = step_times(starts.times[r], mpc.step_minutes, h)
            clock.append([self.clock(t) for t in times])
            weights.append(mpc.energy_weights.at([starts.times[r], *times[:-1]]))  # the objective's, as the planner
            forecast = mpc.forecasts(starts.weathers[r])
            exo.append(mpc.exogenous_seen(forecast, times))
            outdoor.append(forecast.file.truth(times)[:, 0])
            applies.append(mpc.comfort_times(times))
            bounds.append(mpc.comfort_times.bounds(times))
        f32 = lambda a: th.as_tensor(np.asarray(a), dtype=th.float32)  # noqa: E731
        obs = np.stack([starts.obs[r] for r in rows])
        return {
            "obs": f32(obs),
            "prev": f32(np.stack([starts.prev[r] for r in rows])),
            "exo": f32(np.stack(exo)),
            "outdoor": f32(np.stack(outdoor)),
            "applies": f32(np.stack(applies)),
            "bounds": f32(np.stack(bounds)),
            "clock": f32(np.array(clock, np.float32)),
            "weights": f32(np.stack(weights)),
        }

    def act(self, obs: th.Tensor) -> th.Tensor:
        """The policy's mean action on raw observations [..., n_obs] (SB3's extractor flattens all but the first
        axis, so the batch axes are flattened first)."""
        z = th.clamp((obs - self.mean) / self.scale, -self.clip, self.clip).reshape(-1, obs.shape[-1])
        latent = self.policy.mlp_extractor.forward_actor(self.policy.extract_features(z))
        return self.policy.action_net(latent).reshape(*obs.shape[:-1], -1)

    def rebuild(self, obs0: th.Tensor, s: th.Tensor, outdoor: th.Tensor, clock: th.Tensor) -> th.Tensor:
        """Each member's observation from its predicted state: [E, B, n_obs]."""
        e = s.shape[0]
        obs = obs0.expand(e, -1, -1).clone()
        obs[..., self.temp_at] = s[..., : self.k]
        if self.layout.hvac:
            obs[..., self.hvac_at] = s[..., self.k + 1 :]
            obs[..., self.total_at] = s[..., self.k :].sum(-1, keepdim=True)
        else:
            obs[..., [self.layout.sensors.index(n) for n in self.layout.energy]] = s[..., self.k :]
        if self.outdoor_at:
            obs[..., self.outdoor_at] = outdoor[None, :, None].expand(e, -1, len(self.outdoor_at))
        if clock.shape[-1]:  # the time and schedule features at the step's end, after the sensors
            obs[..., self.n_sensors : self.n_sensors + clock.shape[-1]] = clock.expand(e, -1, -1)
        return obs

    def cost(self, b: dict, comfort_weight: float) -> tuple[th.Tensor, dict]:
        """The policy's cost on the batch `b` over the horizon, and its parts. Each step's is the planner's
        (runtime/planner.py `Planner._add_step_cost`, where the formula is written), term for term in torch for the
        gradient: energy (each part as the objective weighs it) x power_weight, the comfort surrogate (K beyond the
        bounds shrunk by the margin, summed over zones; the members' mean or worst) where the band applies x
        `comfort_weight` / margin / K, x 1 + `terminal_weight` on the horizon's last step, and the members' spread x
        `disagreement_weight`; means over the batch (a loss), where the planner sums per candidate. The student's
        own: its `comfort_weight` and margin (`student_comfort_weight`, `student_margin`), and the moves term."""
        m, s_, k = self.model, self.s, self.k
        e = s_.members
        state = th.as_tensor(self.layout.state(b["obs"][:, : self.n_sensors].numpy()))
        s = state.expand(e, -1, -1)
        prev = b["prev"].expand(e, -1, -1)
        obs = b["obs"].expand(e, -1, -1)
        margin, move_weight = self.margin_c, self.move_weight
        parts = {"energy": 0.0, "comfort": 0.0, "spread": 0.0, "moves": 0.0}
        self.applied: list[th.Tensor] = []  # each step's actions [E, B, A], for inspection
        for h in range(s_.horizon):
            raw = self.act(obs)
            # outside the data's support or a jump beyond the planner's largest increment: penalized (the model
            # was never shown either), and the support enforced as the planner's is
            outside = th.relu(raw - self.high) + th.relu(self.low - raw)
            a = th.maximum(th.minimum(raw, self.high), self.low)
            self.applied.append(a.detach())
            jump = th.relu((a - prev).abs() - s_.max_increment)
            parts["moves"] = parts["moves"] + move_weight * ((outside**2).sum(-1) + (jump**2).sum(-1)).mean()
            x = b["exo"][:, h].expand(e, -1, -1)
            inputs = (th.cat([s, prev, a, x], dim=-1) - m.x_mean) / m.x_std
            out = m(inputs) * m.y_std + m.y_mean
            s = next_state(self.layout, s, out)
            temps = s[..., :k]
            energy = (out[..., k:] * b["weights"][:, h]).sum(-1)  # each part as the run's objective weighs it
            parts["energy"] = parts["energy"] + energy.mean() * self.mpc.power_weight
            lo = b["bounds"][:, h, :, 0] + margin
            hi = b["bounds"][:, h, :, 1] - margin
            over = th.relu(th.maximum(lo - temps, temps - hi)).sum(-1)  # [E, B]
            over = over.max(0).values if s_.comfort_risk == "worst" else over.mean(0)
            terminal = 1 + s_.terminal_weight if h == s_.horizon - 1 else 1  # x 1: the same bits
            comfort = (over * b["applies"][:, h]).mean() * comfort_weight / margin / k * terminal
            parts["comfort"] = parts["comfort"] + comfort
            parts["spread"] = parts["spread"] + temps.std(0).sum(-1).mean() * s_.disagreement_weight
            prev = a
            obs = self.rebuild(b["obs"], s, b["outdoor"][:, h], b["clock"][:, h])
        total = sum(parts.values())
        return total, {n: float(v.detach()) if th.is_tensor(v) else float(v) for n, v in parts.items()}


def widen(model, stats, clock: Clock, building):
    """The policy and its normalizer with the clock's features as inputs after the sensors: the new inputs' weights
    start at zero (the widened policy acts as the narrow one did), their normalizer from a week of them."""
    week = [dt.datetime(2013, 1, 7) + dt.timedelta(minutes=15 * i) for i in range(7 * building.steps_per_day)]
    values = np.array([clock(t) for t in week])
    n = model.observation_space.shape[0] + values.shape[1]

    class Shell(gym.Env):
        observation_space = gym.spaces.Box(-np.inf, np.inf, (n,), np.float32)
        action_space = model.action_space

    wide = type(model)(type(model.policy), Shell(), policy_kwargs=model.policy_kwargs, device="cpu", seed=0)
    state = wide.policy.state_dict()
    for key, value in model.policy.state_dict().items():
        if state[key].shape == value.shape:
            state[key] = value
        else:  # a first layer: the old inputs' weights, zeros for the new
            state[key] = th.zeros_like(state[key])
            state[key][:, : value.shape[1]] = value
    wide.policy.load_state_dict(state)
    widened = dataclasses.replace(stats, obs_mean=np.concatenate([stats.obs_mean, values.mean(0)]),
                                  obs_var=np.concatenate([stats.obs_var, values.var(0) + 1e-6]))  # fmt: skip
    return wide, widened


def train(rollouts: Rollouts, starts: Starts, optimizer, updates: int, batch: int, comfort_weight: float,
          rng: np.random.Generator, report=None) -> dict:  # fmt: skip
    """`updates` gradient steps of the policy on batches of `starts`; the last step's cost parts. `report(u, loss,
    parts)` sees every step."""
    params = [p for g in optimizer.param_groups for p in g["params"]]
    parts: dict = {}
    with frozen(rollouts.model):
        for u in range(updates):
            b = rollouts.batch(starts, rng.integers(0, len(starts), batch))
            loss, parts = rollouts.cost(b, comfort_weight)
            optimizer.zero_grad()
            loss.backward()
            th.nn.utils.clip_grad_norm_(params, 1.0)
            optimizer.step()
            if report is not None:
                report(u, loss.item(), parts)
    return parts


@contextlib.contextmanager
def frozen(module: th.nn.Module):
    """The ensemble's weights out of autograd meanwhile: the gradient passes through them to the policy, and the
    ensemble's own fits (Dyna refits) find them as they were."""
    flags = [p.requires_grad for p in module.parameters()]
    for p in module.parameters():
        p.requires_grad_(False)
    try:
        yield module
    finally:
        for p, flag in zip(module.parameters(), flags, strict=True):
            p.requires_grad_(flag)


def train_student(mpc: MPC, building, model, env, starts: Starts, cfg, seed: int) -> dict:
    """`train --algorithm mpc --mpc student=gradient`: the run's student (an SB3 actor-critic and its VecNormalize)
    trained `student_updates` steps through the run's model (`cfg`: its TrainConfig: the settings and the clock's
    features its observation carries); the report distill.json keeps."""
    s = cfg.mpc
    clock = Clock(cfg.time_features, model_schedule(cfg.building) if cfg.schedule_features else None)
    policy = model.policy
    rollouts = Rollouts(mpc, building, NormStats.of(env), policy, clock, s.student_margin)
    params = [*policy.mlp_extractor.policy_net.parameters(), *policy.action_net.parameters()]
    optimizer = th.optim.Adam(params, lr=s.student_learning_rate)
    cost = train(rollouts, starts, optimizer, s.student_updates, s.student_batch, s.student_comfort_weight,
                 np.random.default_rng(seed))  # fmt: skip
    return {"student": "gradient", "starts": len(starts), "updates": s.student_updates,
            "margin_c": rollouts.margin_c, "cost": {k: round(v, 4) for k, v in cost.items()}}  # fmt: skip
