"""What the learner reports while it trains: per-weather episode metrics, throughput and update times."""

from __future__ import annotations

import re
import time
from pathlib import Path

import pandas as pd
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.logger import Logger, TensorBoardOutputFormat
from tqdm import tqdm

from parallel_eplus import io
from parallel_eplus.evaluation.building_table import RATIOS
from parallel_eplus.training.config import STEPS_PER_YEAR

# The built-in controls' episode summaries on the training weathers (written by `--init-from-baseline`, which runs
# them anyway): each episode's BOPTEST figures are then also reported as ratios to them.
BUILTIN_FILE = "builtin.csv"


def episodes_per_weather(episodes_csv: Path) -> dict[str, int]:
    """The run's finished episodes by weather, from its episodes.csv."""
    if not episodes_csv.is_file():
        return {}
    counts = pd.read_csv(episodes_csv, usecols=["weather"])["weather"].value_counts().sort_index()
    return {str(k): int(v) for k, v in counts.items()}


class WeatherRuns(TensorBoardOutputFormat):
    """SB3's TensorBoard output, each weather's episode metrics in a run of their own.

    `episode/<weather>/<tag>` goes to `<folder>/weather-<weather>/` as `episode/<tag>`, so TensorBoard draws
    one chart per tag with a line per weather (and per trial of a sweep: `<trial>/weather-CA`); everything
    else stays in `<folder>`. Written and flushed on the logger's dump, as SB3 writes its own.
    """

    EPISODE = re.compile(r"episode/([^/]+)/(.+)")

    def __init__(self, folder: str):
        super().__init__(folder)
        self.folder = Path(folder)
        self.weathers: dict[str, TensorBoardOutputFormat] = {}

    def write(self, key_values: dict, key_excluded: dict, step: int = 0) -> None:
        split: dict[str, dict] = {}
        rest = {}
        for key, value in key_values.items():
            m = self.EPISODE.fullmatch(key)
            if m:
                split.setdefault(m[1], {})[f"episode/{m[2]}"] = (value, key_excluded.get(key))
            else:
                rest[key] = value
        super().write(rest, {k: key_excluded.get(k) for k in rest}, step)
        for weather, values in split.items():
            if weather not in self.weathers:  # a weather given as a file: its name
                name = re.sub(r"[^A-Za-z0-9._-]+", "-", Path(weather).stem if "/" in weather else weather)
                self.weathers[weather] = TensorBoardOutputFormat(str(self.folder / f"weather-{name}"))
            self.weathers[weather].write({k: v for k, (v, _) in values.items()},
                                         {k: x for k, (_, x) in values.items()}, step)  # fmt: skip

    def close(self) -> None:
        super().close()
        for writer in self.weathers.values():
            writer.close()


def tensorboard_logger(folder: Path) -> Logger:
    """The run's SB3 logger: TensorBoard in `folder`, each weather's episode metrics in a sub-run (WeatherRuns)."""
    return Logger(str(folder), [WeatherRuns(str(folder))])


def builtin_figures(path: Path) -> dict[str, dict[str, float]]:
    """weather -> the built-in controls' BOPTEST figures (`RATIOS`) from `BUILTIN_FILE`; empty without one."""
    if not path.is_file():
        return {}
    table = pd.read_csv(path)
    keys = [k for k in RATIOS if k in table.columns]
    return {str(r["weather"]): {k: float(r[k]) for k in keys} for _, r in table.iterrows()}


class EpisodeMetrics(BaseCallback):
    """Per finished episode, tagged by weather: reward, power, zone temperatures, share in range
    (`episode/<weather>/<tag>`, which WeatherRuns writes as one TensorBoard run per weather).

    Also appends every episode's summary to runs/<name>/episodes.csv, logs throughput and counts the
    episodes cut short by an EnergyPlus failure (restarted, within the restart budget).
    """

    KEYS = {
        "reward_mean": "reward_per_step",
        "power_kw": "power_kw",
        "it_power_kw": "it_power_kw",
        "hvac_power_kw": "hvac_power_kw",
        "energy_kwh": "energy_kwh",  # BOPTEST's figures (buildings/scoring/comfort.py)
        "peak_power_kw": "peak_power_kw",
        "discomfort_kh": "discomfort_kh",
        "hvac_energy_kwh_m2": "hvac_energy_kwh_m2",  # BOPTEST's ener_tot, cost_tot, emis_tot (scoring/kpis.py)
        "energy_kwh_m2": "energy_kwh_m2",
        "cost_m2": "cost_m2",
        "emissions_kg_m2": "emissions_kg_m2",
    }  # and every reward temperature's mean and std, and the share in band where it applies (`_tags`)

    def __init__(self, episodes_csv: Path, progress: tqdm | None, steps_per_year: int = STEPS_PER_YEAR):
        """`steps_per_year`: the building's control steps in a year (the data center's 15-minute steps)."""
        super().__init__()
        self.episodes_csv = episodes_csv
        self.progress = progress
        self.steps_per_year = steps_per_year
        self.episodes = 0
        self.restarts = 0
        self.per_weather = episodes_per_weather(episodes_csv)  # a resumed run counts on from its earlier episodes
        self.builtin = builtin_figures(episodes_csv.parent / BUILTIN_FILE)
        self._columns: list[str] | None = None  # episodes.csv's header: every row is written in its columns
        self._t0 = time.monotonic()
        self._steps0 = 0

    def _on_training_start(self) -> None:
        self._t0 = time.monotonic()
        self._steps0 = self.num_timesteps

    def _on_step(self) -> bool:
        for info in self.locals["infos"]:
            if "energyplus_error" in info:
                self.restarts += 1
            final = info.get("final_info")
            if final and "episode_summary" in final:
                self._record(final["episode_summary"], info.get("episode", {}).get("r"))
        if self.progress is not None:
            self.progress.update(self.training_env.num_envs)
        return True

    def _record(self, summary: dict, episode_return: float | None) -> None:
        self.episodes += 1
        weather = summary.get("weather", "?")
        self.per_weather[weather] = self.per_weather.get(weather, 0) + 1
        reference = self.builtin.get(weather, {})
        summary = summary | {f"{k}_vs_builtin": summary[k] / v for k, v in reference.items() if k in summary and v}
        for key, tag in self._tags(summary).items():
            self.logger.record_mean(f"episode/{weather}/{tag}", summary[key])
        if episode_return is not None:
            self.logger.record_mean(f"episode/{weather}/return", episode_return)
        row = {"timesteps": self.num_timesteps, **summary}
        new = not self.episodes_csv.is_file()
        if self._columns is None:  # a resumed run's file keeps its header: a summary with more figures (the bill's,
            # since 2026-11-28) must not write rows wider than it
            self._columns = list(row) if new else self.episodes_csv.open().readline().rstrip("\n").split(",")
        row = {k: row.get(k) for k in self._columns}
        io.append_text(self.episodes_csv, io.csv_rows(row, header=new))
        if self.progress is not None:
            self.progress.set_postfix(episodes=self.episodes, last=f"{weather} {summary.get('power_kw', 0):.0f} kW")

    def _tags(self, summary: dict) -> dict[str, str]:
        """Summary key -> TensorBoard tag: the fixed ones, each reward temperature's, the share in band."""
        tags = {k: t for k, t in self.KEYS.items() if k in summary}
        tags |= {k: k for k in summary if k.endswith(("_temp_mean", "_temp_std", "_vs_builtin"))}
        tags |= {k: k for k in summary if k.startswith("noise_")}  # the episode's weather noise (weather_noise.py)
        if "in_band_pct" in summary:  # the data center's tag names its band, as its runs always have
            tags["in_band_pct"] = "in_22_25_pct" if "west_temp_mean" in summary else "in_band_pct"
        return tags

    def _on_rollout_end(self) -> None:
        elapsed = time.monotonic() - self._t0
        if elapsed > 0:
            rate = (self.num_timesteps - self._steps0) / elapsed
            self.logger.record("throughput/env_steps_per_s", rate)
            self.logger.record("throughput/sim_years_per_hour", rate * 3600 / self.steps_per_year)
        self.logger.record("throughput/episodes", self.episodes)
        self.logger.record("throughput/worker_restarts", self.restarts)
        for weather, count in self.per_weather.items():
            self.logger.record(f"episodes/{weather}", count)


class UpdateTimer(BaseCallback):
    """Wall time of each TRPO update (between rollouts), and of `learn` from the first observations on."""

    def __init__(self):
        super().__init__()
        self.updates: list[float] = []
        self._t: float | None = None
        self.learn_s = 0.0
        self.learn_steps = 0

    def _on_training_start(self) -> None:  # SB3 has reset the env: every worker has its first observation
        self._t0, self._steps0 = time.perf_counter(), self.num_timesteps

    def _on_training_end(self) -> None:
        self._update_done()  # the last rollout's update, which no rollout follows
        self.learn_s = time.perf_counter() - self._t0
        self.learn_steps = self.num_timesteps - self._steps0

    def _on_rollout_end(self) -> None:
        self._t = time.perf_counter()

    def _on_rollout_start(self) -> None:
        self._update_done()

    def _update_done(self) -> None:
        if self._t is not None:
            self.updates.append(time.perf_counter() - self._t)
            self.logger.record("throughput/update_s", self.updates[-1])
            self._t = None

    def _on_step(self) -> bool:
        return True


class CallbackHost:
    """What SB3's callbacks read of a model (EpisodeMetrics, RunStatus): the env, the logger, the step count; for a
    learner that is not an SB3 model (training/mpc.py's Dyna loop)."""

    def __init__(self, env, logger):
        self.env, self.logger, self.num_timesteps = env, logger, 0

    def get_env(self):
        return self.env
