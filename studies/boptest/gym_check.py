"""BOPTEST-Gym's `BoptestGymEnv`, unmodified, against `parallel-eplus boptest`: its environment checked by SB3's
env checker, a few episodes of a PPO agent trained on it, and the trained agent's test episode's KPIs.

    .venv/bin/parallel-eplus boptest --port 8000 &
    git clone https://github.com/ibpsa/project1-boptest-gym /tmp/project1-boptest-gym   # not a project dependency
    .venv/bin/python studies/boptest/gym_check.py /tmp/project1-boptest-gym --url http://127.0.0.1:8000

BOPTEST-Gym needs only requests, gymnasium, scipy, matplotlib and Stable-Baselines3, all in the project's venv.
"""

from __future__ import annotations

import argparse
import json
import sys
import time


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("gym", help="a checkout of ibpsa/project1-boptest-gym")
    p.add_argument("--url", default="http://127.0.0.1:8000")
    p.add_argument("--testcase", default="office-small")
    p.add_argument("--episode-days", type=float, default=1.0)
    p.add_argument("--timesteps", type=int, default=480, help="PPO's training steps")
    p.add_argument("--out", default="/tmp/boptest-gym-logs")
    args = p.parse_args()
    sys.path.insert(0, args.gym)
    from boptestGymEnv import BoptestGymEnv, NormalizedObservationWrapper  # noqa: E402 - BOPTEST-Gym's own
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_checker import check_env

    t0 = time.perf_counter()
    env = BoptestGymEnv(
        url=args.url, testcase=args.testcase, actions=["heating_setpoint_u", "cooling_setpoint_u"],
        observations={"time": (0, 604800), "core_temp_y": (280.0, 310.0), "TDryBul": (250.0, 320.0),
                      "PriceElectricPowerDynamic": (0.0, 1.0)},
        predictive_period=3 * 3600, random_start_time=False, start_time=10 * 86400, warmup_period=86400,
        max_episode_length=int(args.episode_days * 86400), step_period=1800, log_dir=args.out,
        scenario={"electricity_price": "dynamic"},
    )  # fmt: skip
    check_env(env, warn=True)
    env = NormalizedObservationWrapper(env)
    model = PPO("MlpPolicy", env, n_steps=48, batch_size=48, seed=0, verbose=0)
    t1 = time.perf_counter()
    model.learn(total_timesteps=args.timesteps)
    t2 = time.perf_counter()
    obs, _ = env.reset()
    done, steps = False, 0
    while not done:
        action, _ = model.predict(obs, deterministic=True)
        obs, reward, terminated, truncated, _ = env.step(action)
        done, steps = terminated or truncated, steps + 1
    kpis = env.unwrapped.get_kpis()
    t3 = time.perf_counter()
    print(json.dumps({"check_env_s": round(t1 - t0, 1), "train_steps": args.timesteps,
                      "train_s": round(t2 - t1, 1), "test_steps": steps, "test_s": round(t3 - t2, 1),
                      "kpis": kpis}, indent=2))  # fmt: skip
    env.unwrapped.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
