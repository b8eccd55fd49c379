"""Pilot: a policy network learned *through* the planner's model (issue 51), not copied from the planner's actions.

The policy (the mpc run's distilled network, its observation normalizer unchanged, so `export` and `serve` take
it as they are) is trained by gradient descent on the planner's own cost over the planner's horizon, the cost's
gradient taken through the learned ensemble (SVG(H), Heess et al. 2015; "analytic policy gradients" through a
learned model): from real states, every member rolls its own trajectory (as the planner's, PETS's TS-inf), the
policy acting at each step on the observation rebuilt from the member's predicted state (the zone temperatures and
energy parts; the outdoor dry bulb from the weather file; any other sensor held at its start), and the step's
cost is the planner's: energy x power_weight, the comfort surrogate beyond the band shrunk by the margin where the
band applies, and the members' spread. An increment beyond the planner's `max_increment` and an action outside the
data's support are penalized, since the model knows nothing there. Rounds alternate: the policy runs in EnergyPlus
on the training weathers (CA, CO, FL) at dates across the year, its states join the start states (the policy's own
states: no covariate shift), and it is trained on them again.

    .venv/bin/python studies/model-gradient/pilot.py [--rounds 4] [--out ../model-gradient]

Each round's policy is saved as <out>/round<r>/model.zip (+ vecnormalize.npz); evaluate it with `evaluate --policy`.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import logging
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np
import torch as th
from tqdm import tqdm

from parallel_eplus.buildings.weather_forecast import PerfectForecast
from parallel_eplus.engine.config import SimulationConfig
from parallel_eplus.evaluation.controllers import Controller
from parallel_eplus.evaluation.sweep import run_local
from parallel_eplus.learning.model_based.control import MPC
from parallel_eplus.learning.model_based.dataset import next_state
from parallel_eplus.learning.model_based.features import step_times
from parallel_eplus.learning.rollout import ALGORITHMS
from parallel_eplus.learning.saved_models import load_model
from parallel_eplus.runs.norm_stats import read_stats
from parallel_eplus.runs.policy_files import normalization_file, stats_target

log = logging.getLogger("model-gradient")
ROOT = Path(__file__).resolve().parents[2]
RUN = ROOT / "results/model-based/datacenter-2zone/runs/datacenter-2zone-mpc-seed0"
OUTDOOR = "site outdoor air drybulb temperature"


class Starts:
    """Real states the rollouts branch from: observation, the action before it (normalized), time and weather."""

    def __init__(self):
        self.obs, self.prev, self.times, self.weathers = [], [], [], []

    def add(self, obs, prev, when, weather) -> None:
        self.obs.append(np.asarray(obs, np.float32))
        self.prev.append(np.asarray(prev, np.float32))
        self.times.append(when)
        self.weathers.append(weather)

    def __len__(self) -> int:
        return len(self.obs)


class Rollouts:
    """The policy's cost over the planner's horizon through the ensemble, differentiable in the policy's weights."""

    def __init__(self, mpc: MPC, building, stats, policy):
        self.mpc, self.layout, self.s = mpc, mpc.layout, mpc.settings
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
        assert names[self.k :] == (("non_hvac_w", *self.layout.hvac) if self.layout.hvac else self.layout.energy)

    def batch(self, starts: Starts, rows: np.ndarray) -> dict:
        """The rows' inputs over the horizon: observation, previous action, exogenous inputs, outdoor dry bulb,
        whether the band applies and the bounds at each step's end."""
        h, mpc = self.s.horizon, self.mpc
        exo, outdoor, applies, bounds = [], [], [], []
        for r in rows:
            times = step_times(starts.times[r], mpc.step_minutes, h)
            forecast = mpc.forecasts(starts.weathers[r])
            exo.append(forecast.at(times))
            outdoor.append(forecast.file.truth(times)[:, 0])
            applies.append(mpc.comfort_times(times))
            bounds.append(mpc.comfort_times.bounds(times))
        f32 = lambda a: th.as_tensor(np.asarray(a), dtype=th.float32)  # noqa: E731
        obs = np.stack([starts.obs[r] for r in rows])
        return {"obs": f32(obs), "prev": f32(np.stack([starts.prev[r] for r in rows])), "exo": f32(np.stack(exo)),
                "outdoor": f32(np.stack(outdoor)), "applies": f32(np.stack(applies)), "bounds": f32(np.stack(bounds))}

    def act(self, obs: th.Tensor) -> th.Tensor:
        """The policy's mean action on raw observations [..., n_obs] (SB3's extractor flattens all but the first
        axis, so the batch axes are flattened first)."""
        z = th.clamp((obs - self.mean) / self.scale, -self.clip, self.clip).reshape(-1, obs.shape[-1])
        latent = self.policy.mlp_extractor.forward_actor(self.policy.extract_features(z))
        return self.policy.action_net(latent).reshape(*obs.shape[:-1], -1)

    def rebuild(self, obs0: th.Tensor, s: th.Tensor, outdoor: th.Tensor) -> th.Tensor:
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
        return obs

    def cost(self, b: dict, comfort_weight: float, move_weight: float = 10.0) -> tuple[th.Tensor, dict]:
        m, s_, k = self.model, self.s, self.k
        e = s_.members
        state = th.as_tensor(self.layout.state(b["obs"][:, : self.n_sensors].numpy()))
        s = state.expand(e, -1, -1)
        prev = b["prev"].expand(e, -1, -1)
        obs = b["obs"].expand(e, -1, -1)
        margin = self.mpc.margin_c
        parts = {"energy": 0.0, "comfort": 0.0, "spread": 0.0, "moves": 0.0}
        for h in range(s_.horizon):
            raw = self.act(obs)
            # outside the data's support or a jump beyond the planner's largest increment: penalized (the model
            # was never shown either), and the support enforced as the planner's is
            outside = th.relu(raw - self.high) + th.relu(self.low - raw)
            a = th.maximum(th.minimum(raw, self.high), self.low)
            jump = th.relu((a - prev).abs() - s_.max_increment)
            parts["moves"] = parts["moves"] + move_weight * ((outside**2).sum(-1) + (jump**2).sum(-1)).mean()
            x = b["exo"][:, h].expand(e, -1, -1)
            inputs = (th.cat([s, prev, a, x], dim=-1) - m.x_mean) / m.x_std
            out = m(inputs) * m.y_std + m.y_mean
            s = next_state(self.layout, s, out)
            temps = s[..., :k]
            parts["energy"] = parts["energy"] + out[..., k:].sum(-1).mean() * self.mpc.power_weight
            lo = b["bounds"][:, h, :, 0] + margin
            hi = b["bounds"][:, h, :, 1] - margin
            over = th.relu(th.maximum(lo - temps, temps - hi)).sum(-1)  # [E, B]
            if s_.comfort_risk == "worst":
                over = over.max(0).values
            else:
                over = over.mean(0)
            parts["comfort"] = parts["comfort"] + (over * b["applies"][:, h]).mean() * comfort_weight / margin / k
            parts["spread"] = parts["spread"] + temps.std(0).sum(-1).mean() * s_.disagreement_weight
            prev = a
            obs = self.rebuild(b["obs"], s, b["outdoor"][:, h])
        total = sum(parts.values())
        return total, {n: float(v) for n, v in parts.items()}


def collect(policy_act, weathers: list[str], starts_days: list[int], days: int, workers: int, folder: Path,
            starts: Starts | None, building) -> list[dict]:  # fmt: skip
    """The policy (None: the building's own controls) in EnergyPlus on each (weather, start day): its episodes'
    summaries; its states into `starts`."""
    last: dict[str, np.ndarray] = {}
    initial = np.array([2 * (a.initial - a.low) / (a.high - a.low) - 1 for a in building.actions], np.float32)

    def act(obs, info):
        key = f"{info['weather']}"
        action = policy_act(obs)
        if starts is not None:
            starts.add(obs, last.get(key, initial), info["time"], info["weather"])
        last[key] = action
        return action

    controller = Controller("model-gradient", "policy", act=act) if policy_act else Controller("own", "baseline")
    jobs = [(controller, SimulationConfig(weather=w, model=controller.model, run_days=days, start_day=d,
                                          energyplus_csv=False, output_dir=str(folder / f"{w}-{d}")))
            for w in weathers for d in starts_days]  # fmt: skip
    with tqdm(total=len(jobs) * days * building.steps_per_day, unit="step", desc="collect") as bar:
        rows, failures = run_local(jobs, workers, bar, keep_going=True)
    for f in failures:
        log.warning("episode failed: %s", f)
    return rows


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--run", type=Path, default=RUN)
    p.add_argument("--rounds", type=int, default=4)
    p.add_argument("--updates", type=int, default=600, help="gradient steps per round")
    p.add_argument("--batch", type=int, default=128)
    p.add_argument("--lr", type=float, default=3e-4)
    p.add_argument("--days", type=int, default=7, help="each collection episode's length")
    p.add_argument("--workers", type=int, default=1)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--comfort-weight", type=float, help="the comfort term's weight (default: the planner's)")
    p.add_argument("--out", type=Path, default=ROOT.parent / "model-gradient")
    args = p.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s: %(message)s")
    logging.getLogger("parallel_eplus").setLevel(logging.WARNING)
    th.set_num_threads(1)
    th.manual_seed(args.seed)
    rng = np.random.default_rng(args.seed)

    mpc = MPC.load(args.run / "best" / "planner" / "planner.pt")
    for param in mpc.model.parameters():
        param.requires_grad_(False)
    building = __import__("parallel_eplus.buildings.building", fromlist=["load_building"]).load_building(mpc.building)
    source = args.run / "model.zip"
    stats = read_stats(normalization_file(source))
    model = load_model(ALGORITHMS["trpo"], source, device="cpu")
    policy = model.policy
    rollouts = Rollouts(mpc, building, stats, policy)
    params = list(policy.mlp_extractor.policy_net.parameters()) + list(policy.action_net.parameters())
    opt = th.optim.Adam(params, lr=args.lr)
    weathers = ["CA", "CO", "FL"]
    starts = Starts()
    log_rows = []

    def policy_act(obs):
        with th.no_grad():
            a = rollouts.act(th.as_tensor(np.asarray(obs, np.float32)[None]))[0].numpy()
        return np.clip(a, -1, 1)

    for r in range(args.rounds + 1):
        days = sorted(rng.choice(np.arange(1, 365 - args.days, 7), size=2, replace=False).tolist())
        with tempfile.TemporaryDirectory(prefix="model-gradient-") as tmp:
            rows = collect(policy_act, weathers, [1, *days], args.days, args.workers, Path(tmp), starts, building)
            own = collect(None, weathers, [1, *days], args.days, args.workers, Path(tmp) / "own", None, building)
        power = sum(rw["power_kw"] for rw in rows) / sum(rw["power_kw"] for rw in own) - 1
        band = float(np.mean([rw["in_band_pct"] for rw in rows]))
        worst = min(rw["in_band_pct"] for rw in rows)
        log.info("round %d (days %s): power %+.1f %% vs own controls, in band %.2f %% (worst episode %.2f %%); "
                 "%d start states", r, [1, *days], 100 * power, band, worst, len(starts))  # fmt: skip
        log_rows.append({"round": r, "days": [1, *days], "power_vs_own": power, "band_pct": band,
                         "worst_band_pct": worst, "starts": len(starts)})  # fmt: skip
        out = args.out / f"round{r}"
        out.mkdir(parents=True, exist_ok=True)
        model.save(out / "model.zip")
        shutil.copyfile(normalization_file(source), stats_target(out / "model.zip"))
        (out / "config.json").write_text((args.run / "config.json").read_text())
        if r == args.rounds:
            break
        t0 = time.monotonic()
        for u in range(args.updates):
            rows_ = rng.integers(0, len(starts), args.batch)
            b = rollouts.batch(starts, rows_)
            loss, parts = rollouts.cost(b, args.comfort_weight or mpc.comfort_weight)
            opt.zero_grad()
            loss.backward()
            th.nn.utils.clip_grad_norm_(params, 1.0)
            opt.step()
            if u % 100 == 0 or u == args.updates - 1:
                log.info("round %d update %d: loss %.3f %s (%.0f s)", r, u, float(loss),
                         {k: round(v, 3) for k, v in parts.items()}, time.monotonic() - t0)  # fmt: skip
    (args.out / "log.json").write_text(json.dumps(log_rows, indent=1, default=str))


if __name__ == "__main__":
    main()
