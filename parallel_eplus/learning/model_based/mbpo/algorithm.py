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
- `ModelMixBuffer` (model_buffer.py): SAC's replay buffer with the model's transitions beside the real ones; each
  batch draws `real_ratio` of its rows from the real ones, the rest from the model's, both charged today's
  multiplier.

A model's actions stay within the data's support (`MPC.set_support`): a model knows nothing beyond its data.
Started from a planner run (`--init-from runs/<mpc-run>`) it takes that run's ensemble, transitions and the
planner's states as its first start states: a user with a planner gets a network without new simulation first.
Without it, the building's own controls are recorded first (`record_days`) and the ensemble fitted on them.
The ensemble, its data and the start states are saved in runs/<name>/mbpo/ at every refit and checkpoint
(mbpo_state.py, which also finds what a run starts from).
"""

from __future__ import annotations

import logging
import time
from pathlib import Path

import numpy as np
import torch as th
from stable_baselines3.common.callbacks import BaseCallback

from parallel_eplus.buildings.building import load_building
from parallel_eplus.learning.model_based.control.mpc import MPC
from parallel_eplus.learning.model_based.mbpo.state import save_state
from parallel_eplus.learning.model_based.model.dataset import ORIGINS, Transitions, next_state
from parallel_eplus.learning.model_based.model.exogenous import model_schedule
from parallel_eplus.learning.model_based.students.through_model import Clock, Rollouts, Starts
from parallel_eplus.runs.norm_stats import NormStats

log = logging.getLogger(__name__)
MIN_REFIT_ROWS = 960  # ten days of one worker: fewer would pull a fitted ensemble toward a few days' data


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
        self.railed = 0

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
                          a=actions[None, i], x=self.mpc.exogenous_seen(self.mpc.forecasts.of(info), [info["time"]]),
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
