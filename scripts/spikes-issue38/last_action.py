"""Spike (issue 38): does the last action in the distilled policy's observation hold the band in closed loop?

From a `train --algorithm mpc` run's last checkpoint: the planner's observations and actions before DAgger's phase
(executed = planned there), the last action rebuilt per worker. Two small MLPs fitted to the planner's actions:
on the observation alone (today's distilled input) and on the observation plus the last action. Each is then run
in closed loop on January 1-14 of the training weathers (`--weathers`), beside the built-in controls.

    python scripts/spikes-issue38/last_action.py RUN_DIR --out /tmp/la [--weathers CA,FL] [--days 14]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import torch as th

from parallel_eplus.evaluation.controllers import Controller
from parallel_eplus.evaluation.sweep import run_sweep


def fit(x: np.ndarray, y: np.ndarray, seed: int = 0, epochs: int = 30) -> tuple[th.nn.Module, np.ndarray, np.ndarray]:
    th.manual_seed(seed)
    mu, sd = x.mean(0), x.std(0) + 1e-6
    net = th.nn.Sequential(th.nn.Linear(x.shape[1], 64), th.nn.Tanh(), th.nn.Linear(64, 64), th.nn.Tanh(),
                           th.nn.Linear(64, y.shape[1]))  # fmt: skip
    opt = th.optim.Adam(net.parameters(), 1e-3)
    xt, yt = th.as_tensor((x - mu) / sd, dtype=th.float32), th.as_tensor(y, dtype=th.float32)
    rng = np.random.default_rng(seed)
    for _ in range(epochs):
        for b in np.array_split(rng.permutation(len(x)), max(len(x) // 256, 1)):
            loss = ((net(xt[b]) - yt[b]) ** 2).mean()
            opt.zero_grad()
            loss.backward()
            opt.step()
    return net, mu, sd


class Actor:
    def __init__(self, net, mu, sd, last_action: bool, initial: np.ndarray):
        self.net, self.mu, self.sd, self.last_action, self.last = net, mu, sd, last_action, initial.copy()

    def __call__(self, obs: np.ndarray, info: dict) -> np.ndarray:
        x = np.concatenate([obs[:6], self.last]) if self.last_action else obs[:6]
        with th.no_grad():
            a = self.net(th.as_tensor((x - self.mu) / self.sd, dtype=th.float32)).numpy()
        self.last = np.clip(a, -1, 1).astype(np.float32)
        return self.last


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("run", type=Path)
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--weathers", default="CA,FL")
    p.add_argument("--days", type=int, default=14)
    p.add_argument("--workers", type=int, default=3)
    p.add_argument("--dagger-share", type=float, default=0.25)
    args = p.parse_args()
    th.set_num_threads(1)
    cfg = json.loads((args.run / "config.json").read_text())
    ckpt = sorted((args.run / "checkpoints").glob("mpc_*_steps.npz"), key=lambda q: int(q.stem.split("_")[1]))[-1]
    z = np.load(ckpt)
    obs, act = z["policy_obs"], z["policy_act"]
    n = args.workers
    start = cfg["timesteps"] - len(obs)  # the first planner step
    pre = int(((1 - args.dagger_share) * cfg["timesteps"] - start) // n)  # vector steps before DAgger
    obs, act = obs[: pre * n].reshape(pre, n, -1), act[: pre * n].reshape(pre, n, -1)
    last = act[:-1].reshape(-1, act.shape[-1])
    o, a = obs[1:].reshape(-1, obs.shape[-1])[:, :6], act[1:].reshape(-1, act.shape[-1])
    held = np.arange(len(o)) % 5 == 4
    initial = np.array([2 * (23.0 - 10) / 30 - 1, 2 * (23.0 - 10) / 30 - 1, 1.0, 1.0], np.float32)  # unused at t>0
    building = Path(cfg["building"]).stem
    controllers, report = [Controller("Built-in", "baseline", building=building)], {}
    for name, x in (("obs", o), ("obs+last", np.concatenate([o, last], 1))):
        net, mu, sd = fit(x[~held], a[~held])
        with th.no_grad():
            pred = net(th.as_tensor((x[held] - mu) / sd, dtype=th.float32)).numpy()
        report[name] = np.sqrt(((pred - a[held]) ** 2).mean(0)).round(4).tolist()
        print(name, "held-out RMSE (normalized)", report[name], "spread", a[held].std(0).round(4).tolist())
        actor = Actor(net, mu, sd, name != "obs", initial)
        controllers.append(Controller(name, "policy", building=building, factory=lambda actor=actor: Actor(
            actor.net, actor.mu, actor.sd, actor.last_action, act[0, 0])))  # fmt: skip
    table = run_sweep(controllers, args.weathers.split(","), args.days, 2, args.out, progress=False,
                      building=building)  # fmt: skip
    cols = ["controller", "weather", "in_band_pct", "energy_kwh"]
    print(table[cols].to_string())


if __name__ == "__main__":
    main()
