"""`train --algorithm mbpo`: SAC trained on real transitions and on short rollouts of the planner's ensemble
branched from real states (MBPO, Janner et al. 2019), with the comfort constraint's multiplier on both.

The learner is SB3's SAC on the service's workers, as `--algorithm sac`; three pieces make it model-based:
- `ModelRollouts` (a callback): every real step adds its transition to the ensemble's data and its state to the
  start states; every `rollout_every` env steps it branches `rollout_batch` rollouts of `rollout_length` steps
  from those states, SAC's actor acting (stochastically) on the observation rebuilt from the model's prediction
  (through_model.py's `Rollouts`: the clock's features and the outdoor air from the weather file), each branch on
  one member of the ensemble drawn at random; every `--mpc refit_every` env steps it refits the ensemble (Dyna).
- Each model step's reward and comfort cost are the env's own under the constraint: `-power_weight` x the
  objective's energy, and `Comfort.cost` of the predicted zone temperatures against the bounds at that time.
- `ModelMixBuffer`: SAC's replay buffer with the model's transitions beside the real ones; each batch draws
  `real_ratio` of its rows from the real ones, the rest from the model's, both charged today's multiplier.

A model's actions stay within the data's support (`MPC.set_support`): a model knows nothing beyond its data.
Started from a planner run (`--init-from runs/<mpc-run>`) it takes that run's ensemble, transitions and the
planner's states as its first start states: a user with a planner gets a network without new simulation first.
Without it, the building's own controls are recorded first (`record_days`) and the ensemble fitted on them.
The ensemble, its data and the start states are saved in runs/<name>/mbpo/ at every refit and checkpoint.
"""

from __future__ import annotations

import datetime as dt
import logging
import time
from pathlib import Path

import numpy as np
import torch as th
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.type_aliases import ReplayBufferSamples

from parallel_eplus.buildings.building import load_building
from parallel_eplus.learning.lagrangian import CostReplayBuffer
from parallel_eplus.learning.model_based.control import MPC, PLANNER_FILE
from parallel_eplus.learning.model_based.dataset import ORIGINS, Transitions, next_state
from parallel_eplus.learning.model_based.exogenous import model_schedule
from parallel_eplus.learning.model_based.through_model import Clock, Rollouts, Starts
from parallel_eplus.runs.norm_stats import NormStats

log = logging.getLogger(__name__)
STATE_DIR = "mbpo"  # runs/<name>/mbpo/: the ensemble, its transitions, the start states
TRANSITIONS, STARTS = "transitions.npz", "starts.npz"
MIN_REFIT_ROWS = 960  # ten days of one worker: fewer would pull a fitted ensemble toward a few days' data


class ModelMixBuffer(CostReplayBuffer):
    """The real transitions (SB3's replay buffer, with their comfort costs) and the model's, sampled together."""

    real_ratio: float = 0.1

    def __init__(self, *args, model_size: int = 100_000, **kwargs):
        super().__init__(*args, **kwargs)
        self.model_size, self.model_pos, self.model_full = model_size, 0, False
        n_obs, n_act = self.obs_shape[0], self.action_dim
        self.m_obs = np.zeros((model_size, n_obs), np.float32)
        self.m_next = np.zeros((model_size, n_obs), np.float32)
        self.m_act = np.zeros((model_size, n_act), np.float32)
        self.m_reward = np.zeros(model_size, np.float32)
        self.m_cost = np.zeros(model_size, np.float32)

    def model_rows(self) -> int:
        return self.model_size if self.model_full else self.model_pos

    def add_model(self, obs, action, reward, cost, next_obs) -> None:
        """Model transitions (raw observations, as the real ones are kept); the oldest are overwritten."""
        for i in range(len(obs)):
            j = self.model_pos
            self.m_obs[j], self.m_act[j], self.m_next[j] = obs[i], action[i], next_obs[i]
            self.m_reward[j], self.m_cost[j] = reward[i], cost[i]
            self.model_pos = (j + 1) % self.model_size
            self.model_full |= self.model_pos == 0

    def sample(self, batch_size: int, env=None) -> ReplayBufferSamples:
        rows = self.model_rows()
        n_model = 0 if rows == 0 else int(round(batch_size * (1 - self.real_ratio)))
        if self.size() == 0:  # nothing real yet (a run started from a planner's data): the model's alone
            n_model = batch_size
        parts = [super().sample(batch_size - n_model, env)] if n_model < batch_size else []
        if n_model:
            idx = np.random.randint(0, rows, size=n_model)
            rewards = self.m_reward[idx] - self.multiplier * self.m_cost[idx]
            data = (
                self._normalize_obs(self.m_obs[idx], env), self.m_act[idx], self._normalize_obs(self.m_next[idx], env),
                np.zeros((n_model, 1), np.float32), self._normalize_reward(rewards.reshape(-1, 1), env),
            )  # fmt: skip
            parts.append(ReplayBufferSamples(*tuple(map(self.to_torch, data))))
        joined = [None if t[0] is None else th.cat(t) for t in zip(*parts, strict=True)]  # SB3's `discounts`: None
        return ReplayBufferSamples(*joined)


class ModelRollouts(BaseCallback):
    """The ensemble beside SAC: its data from every real step, its refits, and the rollouts it adds."""

    def __init__(self, cfg, mpc: MPC, data: Transitions, starts: Starts, state_dir: Path):
        super().__init__()
        self.cfg, self.s, self.mpc, self.data, self.starts = cfg, cfg.mbpo, mpc, data, starts
        self.state_dir = state_dir
        self.building = load_building(cfg.building)
        self.clock = Clock(cfg.time_features, model_schedule(cfg.building) if cfg.schedule_features else None)
        self.comfort = self.building.comfort
        self.margin = cfg.comfort.margin_c
        self.rng = np.random.default_rng(cfg.seed + 7)
        self.generated = self.railed = 0

    def _on_training_start(self) -> None:
        n = self.training_env.num_envs
        self.model.replay_buffer.real_ratio = self.s.real_ratio
        self.prev = np.tile(self.mpc.initial, (n, 1))
        self.step_of = np.zeros(n, int)
        self.episode_of = np.arange(n) + 1000 * (1 + self.num_timesteps // 1000) + 10**6
        self.rollouts = Rollouts(self.mpc, self.building, NormStats.of(self.training_env), self.model.policy,
                                 self.clock, self.margin)  # fmt: skip
        self.infos: list[dict] = [{} for _ in range(n)]
        self.temps = [self.mpc.layout.sensors.index(t) for t in self.mpc.layout.temperatures]
        if self.s.rail_k is not None:
            self.model.guard = self.rail
        if self.num_timesteps == 0 and len(self.starts):
            self.pretrain()

    def rail(self, action: np.ndarray, buffer_action: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """A worker with a zone more than `rail_k` outside the band is steered by the planner for that step (as
        `--algorithm mpc`'s DAgger phase steers its student): SAC's first steps on the data center otherwise drove a
        zone past 100 C before it learned better. The planner's action is what the replay buffer keeps."""
        obs = np.asarray(self.model._last_original_obs)
        low, high = self.building.band
        temps = obs[:, self.temps]
        far = np.any((temps < low - self.s.rail_k) | (temps > high + self.s.rail_k), axis=1)
        far &= np.array(["time" in info for info in self.infos])  # a worker's first step has no info kept yet
        self.railed += int(far.sum())
        if not far.any():
            return action, buffer_action
        rows = np.flatnonzero(far)
        action = np.array(action, np.float32)
        action[rows] = self.mpc.act(obs[rows], [self.infos[i] for i in rows], self.prev[rows])
        return action, action.copy()  # the action space is [-1, 1]: SB3's buffer action is the action itself

    def pretrain(self) -> None:
        """SAC on the model's rollouts alone before its first real step: an untrained SAC acts at random, and on the
        data center random setpoints and flows overheat the zones until EnergyPlus fails (a first pilot: 200 C on
        the roof within 500 steps)."""
        t0, done, chunk = time.perf_counter(), 0, 100
        while done < self.s.pretrain_updates:
            self.generate()
            self.model.train(min(chunk, self.s.pretrain_updates - done), self.model.batch_size)
            done += chunk
        log.info("SAC pretrained on the model: %d updates on %d model transitions (%.0f s)", self.s.pretrain_updates,
                 self.model.replay_buffer.model_rows(), time.perf_counter() - t0)  # fmt: skip
        self.logger.dump(self.num_timesteps)  # the pretrained policy's rollouts (mbpo/model_cost) at step 0

    def _on_step(self) -> bool:
        env, n = self.training_env, self.training_env.num_envs
        obs = np.asarray(self.model._last_original_obs)  # before the step (SB3 stores the step after callbacks)
        new = env.get_original_obs()
        actions, dones, infos = self.locals["buffer_actions"], self.locals["dones"], self.locals["infos"]
        sensors = len(self.mpc.layout.sensors)
        for i in range(n):
            info = infos[i]
            if dones[i] or "time" not in info:  # the next observation is the next episode's first
                self.prev[i], self.step_of[i], self.episode_of[i] = self.mpc.initial, 0, self.episode_of[i] + n
                continue
            applies = float(info.get("comfort_applies", True))
            self.data.add(s=self.mpc.layout.state(obs[None, i, :sensors]), a_prev=self.prev[None, i],
                          a=actions[None, i], x=self.mpc.forecasts.of(info).at([info["time"]]),
                          s_next=self.mpc.layout.state(new[None, i, :sensors]), applies=[applies],
                          episode=[self.episode_of[i]], step=[self.step_of[i]],
                          origin=[ORIGINS.index("policy")])  # fmt: skip
            self.starts.add(new[i], actions[i], info["time"], str(info["weather"]))
            self.prev[i], self.step_of[i] = actions[i], self.step_of[i] + 1
        self.infos = [dict(info) if not done else {} for info, done in zip(infos, dones, strict=True)]
        steps, before = self.num_timesteps, self.num_timesteps - n
        if steps // self.cfg.mpc.refit_every != before // self.cfg.mpc.refit_every:
            self.refit()
        if steps // self.s.rollout_every != before // self.s.rollout_every and len(self.starts):
            self.generate()
        if steps // self.cfg.checkpoint_every != before // self.cfg.checkpoint_every:
            self.save()
        return True

    def _on_training_end(self) -> None:
        self.save()

    # -- the model's transitions ----------------------------------------------------------------
    def generate(self) -> int:
        """`rollout_batch` branches of `rollout_length` model steps into the replay buffer; returns the rows."""
        t0 = time.perf_counter()
        obs, act, reward, cost, nxt = self.rollout(self.rng.integers(0, len(self.starts), self.s.rollout_batch))
        self.model.replay_buffer.add_model(obs, act, reward, cost, nxt)
        self.generated += len(obs)
        self.logger.record("mbpo/model_rows", self.model.replay_buffer.model_rows())
        self.logger.record("mbpo/rollout_s", time.perf_counter() - t0)
        self.logger.record("mbpo/model_reward", float(reward.mean()))
        self.logger.record("mbpo/model_cost", float(cost.mean()))
        self.logger.record("mbpo/railed_steps", self.railed)
        return len(obs)

    @th.no_grad()
    def rollout(self, rows: np.ndarray) -> tuple[np.ndarray, ...]:
        """Branches from the start states `rows`: (obs, action, reward, cost, next obs), raw observations, every
        step of every branch stacked."""
        r, layout, mpc, model = self.rollouts, self.mpc.layout, self.mpc, self.mpc.model
        b = r.batch(self.starts, rows)
        k, e, n_rows = len(layout.temperatures), mpc.settings.members, len(rows)
        member = th.as_tensor(self.rng.integers(0, e, n_rows))
        obs, prev = b["obs"], b["prev"]
        s = th.as_tensor(layout.state(obs[:, : r.n_sensors].numpy()))
        low, high = (th.as_tensor(v) for v in mpc.support)
        space = self.training_env.observation_space
        obs_low, obs_high = (th.as_tensor(np.asarray(v, np.float32)) for v in (space.low, space.high))
        out_rows: list[tuple] = []
        for h in range(self.s.rollout_length):
            z = th.as_tensor(self.training_env.normalize_obs(obs.numpy()), dtype=th.float32)
            a = self.model.policy.actor(z, deterministic=False)
            a = th.maximum(th.minimum(a, high), low)  # within the data's support
            x = b["exo"][:, h]
            inputs = (th.cat([s, prev, a, x], dim=-1).expand(e, -1, -1) - model.x_mean) / model.x_std
            out_all = model(inputs) * model.y_std + model.y_mean  # [E, B, out]
            out = out_all[member, th.arange(n_rows)]
            s_next = next_state(layout, s, out)
            nxt = r.rebuild(b["obs"], s_next[None], b["outdoor"][:, h], b["clock"][:, h])[0]
            nxt = th.maximum(th.minimum(nxt, obs_high), obs_low)  # the observation's range, as the env clips it
            s_next = th.as_tensor(layout.state(nxt[:, : r.n_sensors].numpy()))
            energy = (out[:, k:] * b["weights"][:, h]).sum(-1).numpy()
            temps, bounds, applies = s_next[:, :k].numpy(), b["bounds"][:, h].numpy(), b["applies"][:, h].numpy()
            costs = np.array([self.comfort.cost(tuple(map(float, temps[i])), self.margin, [tuple(bb) for bb in
                              bounds[i]])[0] if applies[i] else 0.0 for i in range(n_rows)], np.float32)  # fmt: skip
            out_rows.append((obs.numpy(), a.numpy(), -self.cfg.reward.power_weight * energy, costs, nxt.numpy()))
            obs, prev, s = nxt, a, s_next
        return tuple(np.concatenate(parts).astype(np.float32) for parts in zip(*out_rows, strict=True))

    # -- the ensemble's refits, its state ---------------------------------------------------------
    def refit(self) -> None:
        if len(self.data) < MIN_REFIT_ROWS:  # a committed planner's ensemble, before the run has seen much
            return
        t0 = time.perf_counter()
        loss = self.mpc.model.fit(self.data, np.arange(len(self.data)), self.cfg.mpc.refit_epochs)
        self.mpc.set_support(self.data.array("a"))
        self.logger.record("model/train_loss", loss)
        self.logger.record("model/rows", len(self.data))
        self.logger.record("model/fit_s", time.perf_counter() - t0)
        log.info("model refitted on %d rows (%.1f s)", len(self.data), time.perf_counter() - t0)
        self.save()

    def save(self) -> None:
        save_state(self.state_dir, self.mpc, self.data, self.starts)


def save_state(folder: Path, mpc: MPC, data: Transitions, starts: Starts) -> None:
    from parallel_eplus import io

    folder.mkdir(parents=True, exist_ok=True)
    mpc.save(folder / PLANNER_FILE)
    with io.atomic_path(folder / TRANSITIONS) as tmp, open(tmp, "wb") as f:  # a file: savez adds no suffix
        data.save(f)
    with io.atomic_path(folder / STARTS) as tmp, open(tmp, "wb") as f:
        np.savez_compressed(f, obs=np.asarray(starts.obs), prev=np.asarray(starts.prev),
                            times=np.asarray(starts.times, "datetime64[s]"), weathers=np.asarray(starts.weathers))


def record_own_controls(cfg, mpc: MPC, data: Transitions, starts: Starts, progress: bool) -> None:
    """`record_days` of the building's own controls on the training weathers, as the policy observes them: their
    transitions into the ensemble's data, their states into the start states."""
    import shutil

    from parallel_eplus.learning.imitation import record_baseline
    from parallel_eplus.learning.model_based.sources import add_baseline

    folder = cfg.run_dir / "baseline-record"
    days = cfg.mbpo.record_days or cfg.run_days
    demos = record_baseline(cfg.building, cfg.weathers, days, cfg.workers, folder,
                            (cfg.time_features, cfg.schedule_features), progress)  # fmt: skip
    comfort = load_building(cfg.building).comfort
    first = int(data.array("episode").max()) + 1 if len(data) else 0
    add_baseline(data, demos, mpc.forecasts, mpc.comfort_times, lambda t, v: comfort.always or comfort.applies(t, v),
                 first)  # fmt: skip
    shutil.rmtree(folder, ignore_errors=True)
    labels = np.array(demos.weathers)
    for weather in dict.fromkeys(demos.weathers):
        rows = np.flatnonzero(labels == weather)
        for r0, r in zip(rows[:-1], rows[1:], strict=True):  # each state after the first, and the action before it
            starts.add(demos.observations[r], demos.actions[r0], demos.times[r], weather)


def load_state(folder: Path, workers: int, seed: int) -> tuple[MPC, Transitions, Starts]:
    """The ensemble, its data and the start states a run saved (or a planner run's: `from_planner_run`)."""
    mpc = MPC.load(folder / PLANNER_FILE, workers, seed)
    data = Transitions.load(folder / TRANSITIONS, mpc.layout)
    with np.load(folder / STARTS) as z:
        times = [t.astype(dt.datetime) for t in z["times"].astype("datetime64[s]")]
        starts = Starts.of(z["obs"], z["prev"], times, [str(w) for w in z["weathers"]])
    return mpc, data, starts


def from_planner_run(run: Path, workers: int, seed: int) -> tuple[MPC, Transitions, Starts]:
    """`--init-from runs/<mpc-run>` (or its planner/ or best/planner/ folder): its ensemble, and where the run kept
    them, every transition it saw (transitions.npz, or its newest checkpoint) and the states of the planner's steps
    (its newest checkpoint) as the first start states. A committed planner (the ensemble alone) starts with
    neither: the run's own steps supply both."""
    from parallel_eplus.learning.model_based.checkpoint import Checkpoint, newest_checkpoint

    folder = run if (run / PLANNER_FILE).is_file() else run / "planner"
    if not (folder / PLANNER_FILE).is_file():
        raise FileNotFoundError(f"--init-from {run}: no planner ({folder / PLANNER_FILE}); give a `train "
                                "--algorithm mpc` run's folder")  # fmt: skip
    run = run if folder != run else (run.parent.parent if run.parent.name == "best" else run.parent)
    mpc = MPC.load(folder / PLANNER_FILE, workers, seed)
    data, starts = Transitions(mpc.layout), Starts()
    try:
        _, data, policy = Checkpoint.load(newest_checkpoint(run), mpc.layout)
    except FileNotFoundError:
        policy = None
    if (run / TRANSITIONS).is_file():  # every transition of a finished run
        data = Transitions.load(run / TRANSITIONS, mpc.layout)
    if policy is not None and len(policy) == 5:
        obs, _, prev, times, weathers = policy
        times = [t.astype(dt.datetime) for t in np.asarray(times).astype("datetime64[s]")]
        starts = Starts.of(obs[len(obs) - len(prev) :], prev, times, [str(w) for w in weathers])
    return mpc, data, starts
