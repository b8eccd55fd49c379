"""`train --init-from-baseline`: start learning from the building's own controls, not from scratch.

Imitation before reinforcement learning (as Gnu-RL, Chen et al. 2019, does with its MPC policy): the model
runs with its own controls on the training weathers; what those controls chose for each of the spec's actions
is read back every timestep through an output variable (the node setpoint, fan flow or thermostat setpoint that
EnergyPlus computed: `ActionSpec.readback`, inferred from the actuator or named in the spec); the policy's mean is
fitted to those choices by supervised learning on the same observations the policy sees, the observation
statistics start from them, and reinforcement learning starts there. The first policy then behaves like the
built-in controls, and learning improves on them instead of rediscovering them.

Timing: observation k (the state after timestep k) is paired with what the controls set during timestep k+1,
as an action chosen on observation k acts during timestep k+1 in the env (engine/eplus_side/bridge.py).

The temperatures the controls regulate (the spec's comfort temperatures) barely move in their record: the
data center's zones stay within 23-24.5 °C all year. A plain clone then learns whatever the temperature happens
to correlate with, and in closed loop, where its own small errors move the zones a kelvin away, it acts on
that spurious slope: cloned on a year of CA, CO and FL it drove both zones to 14 °C (0 % in band) although it
matched the recorded actions to 0.4 K. So the fit also sees copies of the record in which those temperatures are
re-drawn across the band ± `redraw_c` with the same actions (`redraw_copies`): the clone learns to ignore them
and acts on what the controls respond to (load, weather, time), a feed-forward copy of the controls that is
stable in closed loop (98 % in band on 14 days of CA). Reinforcement learning then learns the feedback.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
import torch as th
from stable_baselines3.common.vec_env import VecNormalize
from tqdm import tqdm

from parallel_eplus.buildings.building import load_building
from parallel_eplus.buildings.scaling import from_unit, normalize
from parallel_eplus.buildings.weather.files import weather_label
from parallel_eplus.engine.config import SimulationConfig
from parallel_eplus.engine.episode import reported_rows
from parallel_eplus.learning.settings import ImitationSettings

log = logging.getLogger(__name__)


@dataclass
class Demonstrations:
    """The built-in controls' choices: observations as the policy sees them (before normalization), actions
    normalized to [-1, 1] (and in physical units), and the weather of each row."""

    observations: np.ndarray
    actions: np.ndarray
    physical: np.ndarray
    low: np.ndarray  # each action's bounds (physical units)
    high: np.ndarray
    names: tuple[str, ...] = ()
    weathers: list[str] = field(default_factory=list)
    builtin: list[dict] = field(default_factory=list)  # each weather's episode summary under the built-in controls
    times: list = field(default_factory=list)  # each row's time (the end of the step it observed)
    bounds: np.ndarray | None = None  # each row's zone bounds [N, K, 2] where they follow the thermostat's schedules

    def to_physical(self, actions: np.ndarray) -> np.ndarray:
        return from_unit(np.clip(actions, -1, 1), self.low, self.high)

    def __len__(self) -> int:
        return len(self.observations)


def readbacks(building: str | None) -> list[tuple[str, str]]:
    """(variable, key) per action of the building; an action without one is an error naming what to add."""
    spec = load_building(building).spec
    found = []
    for i, a in enumerate(spec.actions):
        if a.readback is None:
            raise ValueError(
                f"{spec.path}: actions[{i}] ({a.name}): --init-from-baseline needs to read back what the building's "
                'own controls set; name the output variable: readback = { variable = "...", key = "..." }'
            )
        found.append(a.readback)
    return found


def _read_back(csv: Path, wanted: list[tuple[str, str]]) -> np.ndarray:
    """The read-back columns of an episode's eplusout.csv, in the order of `wanted` (matched case-insensitively), at
    the steps they were reported (`reported_rows`)."""
    table = pd.read_csv(csv)
    columns = {c.split(" [")[0].split(" (")[0].strip().upper(): c for c in table.columns}
    picked = []
    for variable, key in wanted:
        name = f"{key}:{variable}".upper()
        if name not in columns:
            raise ValueError(f"{csv}: no column for {key} / {variable} (EnergyPlus reported: {list(columns)[:8]}...)")
        picked.append(columns[name])
    return reported_rows(table, picked)[picked].to_numpy(float)


def record_baseline(
    building: str | None,
    weathers: list[str],
    run_days: int,
    workers: int,
    out_dir: Path,
    features: tuple[bool, bool] = (False, False),
    progress: bool = True,
    forecast_hours: int = 0,
) -> Demonstrations:
    """Run the building's own controls on each weather (`workers` at a time) and pair every observation with what
    those controls set next. `features`: the policy's (time, schedule) observation features."""
    from parallel_eplus.evaluation.controllers import BASELINE_LABEL, Controller, slug
    from parallel_eplus.evaluation.sweep import run_local

    wanted = readbacks(building)
    spec = load_building(building)
    recorded: dict[str, list[np.ndarray]] = {}
    times: dict[str, list] = {}
    bounds: dict[str, list] = {}  # the thermostat's bounds (buildings/scoring/comfort.py), where they move
    comfort = spec.comfort
    empty = np.zeros(0, dtype=np.float32)

    class Recorder(Controller):
        def make(self, building=None):
            def act(obs: np.ndarray, info: dict) -> np.ndarray:
                recorded.setdefault(weather_label(info["weather"]), []).append(np.array(obs, np.float32))
                times.setdefault(weather_label(info["weather"]), []).append(info["time"])
                if comfort.per_step:
                    bounds.setdefault(weather_label(info["weather"]), []).append(comfort.bounds(info))
                return empty

            return act

    controller = Recorder(BASELINE_LABEL, "baseline")
    outputs = tuple((key, variable) for variable, key in wanted)
    jobs = [
        (controller, SimulationConfig(
            weather=w, model="baseline", building=building, run_days=run_days, time_features=features[0],
            schedule_features=features[1], extra_outputs=outputs, energyplus_csv=False, forecast_hours=forecast_hours,
            output_dir=str(out_dir / slug(weather_label(w))),
        ))
        for w in weathers
    ]  # fmt: skip
    total = len(jobs) * run_days * spec.steps_per_day
    with tqdm(total=total, unit="step", desc="record built-in controls", disable=not progress) as bar:
        rows, failures = run_local(jobs, workers, bar, keep_going=True)
    for f in failures:  # a model's own controls can fail on a weather (the CRAC's on CO): clone from the others
        log.warning("the built-in controls did not finish %s (%s): cloning without it", f["weather"], f["error"])
    if not rows:
        raise ValueError("the built-in controls finished no weather: nothing to imitate")
    observations, physical, labels, when, zone_bounds = [], [], [], [], []
    for row in rows:
        weather = row["weather"]
        obs = np.stack(recorded[weather])
        chosen = _read_back(Path(row["episode_dir"]) / "eplusout.csv", wanted)
        if len(chosen) != len(obs):
            raise ValueError(f"{weather}: {len(obs)} observations but {len(chosen)} read-back rows in eplusout.csv")
        observations.append(obs)
        physical.append(chosen)
        labels += [weather] * len(obs)
        when += times[weather]
        zone_bounds += bounds.get(weather, [])
    physical_all = np.concatenate(physical)
    low = np.array([a.low for a in spec.actions])
    high = np.array([a.high for a in spec.actions])
    actions = np.clip(normalize(physical_all, low, high), -1, 1).astype(np.float32)
    names = tuple(a.name for a in spec.actions)
    demos = Demonstrations(np.concatenate(observations), actions, physical_all, low, high, names, labels, rows, when)
    demos.bounds = np.array(zone_bounds, float) if zone_bounds else None
    return demos


def _actor_mean(policy, obs: th.Tensor) -> th.Tensor:
    """The deterministic action before clipping: an on-policy Gaussian's mean; SAC's squashed mean."""
    if hasattr(policy, "actor"):  # SAC
        mean, _, _ = policy.actor.get_action_dist_params(obs)
        return th.tanh(mean)
    features = policy.extract_features(obs, policy.pi_features_extractor)
    return policy.action_net(policy.mlp_extractor.forward_actor(features))


def redrawn(demos: Demonstrations, columns: list[int], band: tuple[float, float], settings: ImitationSettings,
            seed: int = 0) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """(observations, actions) to fit: the record, then `redraw_copies` copies of it whose `columns` (the
    regulated temperatures) are drawn uniformly across the band ± `redraw_c`, each independently."""
    rng = np.random.default_rng(seed)
    obs, actions = [demos.observations], [demos.actions]
    for _ in range(settings.redraw_copies if columns else 0):
        copy = demos.observations.copy()
        copy[:, columns] = rng.uniform(band[0] - settings.redraw_c, band[1] + settings.redraw_c,
                                       (len(copy), len(columns)))  # fmt: skip
        obs.append(copy)
        actions.append(demos.actions)
    return np.concatenate(obs), np.concatenate(actions)


def clone(
    model, env: VecNormalize, demos: Demonstrations, settings: ImitationSettings, seed: int = 0,
    regulated: list[int] = (), band: tuple[float, float] = (0.0, 0.0),
) -> dict:  # fmt: skip
    """Fit `model`'s policy to the demonstrations (observation statistics first; `regulated`: the observation
    columns of the temperatures the controls hold, re-drawn in copies: `redrawn`); returns the fit's report."""
    env.obs_rms.mean = demos.observations.mean(axis=0).astype(np.float64)
    env.obs_rms.var = demos.observations.var(axis=0).astype(np.float64)
    env.obs_rms.count = float(len(demos))
    observations, actions = redrawn(demos, list(regulated), band, settings, seed)
    x = th.as_tensor(env.normalize_obs(observations), dtype=th.float32)
    # Actions at a bound are clipped there by the env anyway; for SAC's tanh keep the targets reachable.
    limit = 0.995 if hasattr(model.policy, "actor") else 1.0
    y = th.as_tensor(np.clip(actions, -limit, limit))
    policy = model.policy
    actor = policy.actor if hasattr(policy, "actor") else policy
    params = [p for name, p in actor.named_parameters() if "value" not in name and not name.startswith("log_std")]
    optimizer = th.optim.Adam(params, lr=settings.learning_rate)
    generator = th.Generator().manual_seed(seed)
    policy.set_training_mode(True)
    for _ in range(settings.epochs):
        order = th.randperm(len(x), generator=generator)
        for start in range(0, len(x), settings.batch_size):
            batch = order[start : start + settings.batch_size]
            loss = th.nn.functional.mse_loss(_actor_mean(policy, x[batch]), y[batch])
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
    policy.set_training_mode(False)
    if hasattr(policy, "log_std"):
        with th.no_grad():
            spread = settings.log_std
            if policy.use_sde:  # noise = latent @ matrix: scale it so its typical spread is exp(log_std)
                x_record = th.as_tensor(env.normalize_obs(demos.observations), dtype=th.float32)
                latent = policy.mlp_extractor.forward_actor(
                    policy.extract_features(x_record, policy.pi_features_extractor)
                )
                spread -= 0.5 * float(th.log((latent**2).sum(dim=1).mean()))
            policy.log_std.fill_(spread)
    elif hasattr(policy, "actor") and not policy.actor.use_sde:  # SAC: its log-std head flat at the same spread
        with th.no_grad():  # (before the tanh: at the clone's mean, about the on-policy clone's spread)
            policy.actor.log_std.weight.zero_()
            policy.actor.log_std.bias.fill_(settings.log_std)
    with th.no_grad():  # on the record itself
        x = th.as_tensor(env.normalize_obs(demos.observations), dtype=th.float32)
        fitted = demos.to_physical(_actor_mean(policy, x).numpy())
    target = demos.to_physical(demos.actions)  # the recorded choice within the action's bounds
    rmse = np.sqrt(((fitted - target) ** 2).mean(axis=0))
    return {"samples": len(demos), "rmse": dict(zip(demos.names, rmse.round(4).tolist(), strict=True))}
