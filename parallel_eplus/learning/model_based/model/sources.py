"""Where the model's data come from before the planner acts: the building's own controls, then exploration.

1. The building's own controls, recorded as `--init-from-baseline` records them (training/imitation.py): every
   observation paired with what those controls set next. They cover the states the building normally visits.
2. Exploration around them: each worker replays the recorded actions of its weather at the same step of the year
   (the built-in controls are mostly feed-forward: schedule and weather) plus an offset that walks toward a target
   drawn uniformly from the actions within `explore_offset` of the record (the default: the whole action box),
   held for 1-8 hours (`explore_hold` control steps at most), by at most `explore_increment` per step (the
   planner's own bound). The savings of a data center sit in a corner (cold supply air, low fan flow) that a
   walk of small random steps around the record never reached (a first version: increments of 0.05 within 0.4 of
   the record kept the fans above 5.9 kg/s, and the planner, held within the data's support, never left the
   built-in controls' corner). A free walk drives the zones out of EnergyPlus's range within a day (44 °C at
   mid-range setpoints); here a rail halves the offset at every step a zone is more than 2 K outside the band and
   makes the point it reached the new target, held for a few steps: the walk settles at the edge of what keeps
   the band in the target's direction (where a first rail, back to the record and held there, kept the walk at
   the record most of the time: most targets in the box are too warm for a data center).
"""

from __future__ import annotations

import logging

import numpy as np

from parallel_eplus.learning.model_based.model.dataset import ORIGINS, Transitions
from parallel_eplus.learning.model_based.model.own_level import OwnLevel

log = logging.getLogger(__name__)


def add_baseline(data: Transitions, demos, mpc, applies_of, first_episode: int,
                 own: np.ndarray | None = None) -> dict[str, np.ndarray]:  # fmt: skip
    """The record's transitions into `data` (one episode per weather); returns each weather's normalized actions.

    `applies_of(time, sensor values)`: whether the band applied to the step ending then (buildings/scoring/comfort.py).
    `own` [A]: the actions whose own setpoints the calendar keeps by date (`Calendar.learn_own`), the others NaN.
    `mpc`: the planner whose forecasts and calendar (control.py's MPC) the record feeds."""
    comfort_times = mpc.comfort_times
    layout = data.layout
    labels = np.array(demos.weathers)
    replay = {}
    for j, weather in enumerate(dict.fromkeys(demos.weathers)):
        rows = np.flatnonzero(labels == weather)
        obs, actions = demos.observations[rows], demos.actions[rows]
        times = [demos.times[r] for r in rows]
        replay[weather] = actions
        if len(rows) < 2:
            continue
        s = layout.state(obs[:, : len(layout.sensors)])
        sensed = [dict(zip(layout.sensors, o[: len(layout.sensors)].tolist(), strict=True)) for o in obs]
        applies = np.array([applies_of(t, v) for t, v in zip(times, sensed, strict=True)], np.float32)
        comfort_times.learn(times[1:], applies[1:], None if demos.bounds is None else demos.bounds[rows][1:])
        if own is not None and own.any():
            comfort_times.learn_own(times[1:], np.where(own[None], actions[:-1], np.nan))
        a_prev = np.concatenate([actions[:1], actions[:-2]])
        x = mpc.exogenous_seen(mpc.forecasts(weather), times[1:])
        data.add(s=s[:-1], a_prev=a_prev, a=actions[:-1], x=x, s_next=s[1:],
                 applies=applies[1:], episode=first_episode + j, step=np.arange(len(rows) - 1),
                 origin=ORIGINS.index("baseline"))  # fmt: skip
    return replay


def record_own_controls(cfg, days: int, data: Transitions, mpc,
                        progress: bool) -> tuple[dict[str, np.ndarray], OwnLevel | None]:  # fmt: skip
    """Record the building's own controls on the run's training weathers (`--init-from-baseline`'s recording)
    into `data`; returns each weather's normalized actions, for `Explorer` to replay, and, with
    `comfort_level=baseline`, their comfort by date (own_level.py). `cfg`: the TrainConfig."""
    import shutil

    from parallel_eplus.buildings.building import load_building
    from parallel_eplus.learning.imitation import record_baseline

    folder = cfg.run_dir / "baseline-record"
    demos = record_baseline(cfg.building, cfg.weathers, days, cfg.workers, folder, progress=progress)
    building = load_building(cfg.building)
    comfort = building.comfort

    def applies(t, values) -> bool:
        return comfort.always or comfort.applies(t, values)

    # the baseline of the actions no thermostat schedule gives (a supply-air node), for `comfort_reference=baseline`
    own = None if cfg.mpc.comfort_reference != "baseline" else np.array([s is None for s in mpc.thermostat_sides])
    replay = add_baseline(data, demos, mpc, applies, 0, own)
    if own is not None and own.any():
        names = [a.name for a, o in zip(building.actions, own, strict=True) if o]
        log.info("the own plan of %s: what the building's own controls set on each date of the record",
                 ", ".join(names))  # fmt: skip
    level = None
    if cfg.mpc.comfort_level == "baseline":
        level = OwnLevel.from_record(demos, data.layout.sensors, list(building.temperatures), comfort, applies,
                                     building.steps_per_day)  # fmt: skip
    shutil.rmtree(folder, ignore_errors=True)
    return replay, level


class Explorer:
    """The recorded actions of each worker's weather at its step, plus an offset walking toward held targets.

    The record runs from January 1: with `steps_per_day`, a step is found by its time of the year (an episode that
    starts later, `--random-start`, explores around the built-in's actions of its own dates), else by its number."""

    def __init__(self, replay: dict[str, np.ndarray], workers: int, increment: float, offset: float,
                 band: tuple[float, float], temperatures: list[int], seed: int = 0, hold: int = 32,
                 steps_per_day: int | None = None):  # fmt: skip
        self.replay, self.step_minutes = replay, 1440 // steps_per_day if steps_per_day else None
        self.rng = np.random.default_rng(seed)
        self.increment, self.limit, self.hold = increment, offset, max(hold, 4)
        self.band, self.temperatures = band, temperatures
        n_actions = next(iter(replay.values())).shape[1]
        self.offset = np.zeros((workers, n_actions), np.float32)
        self.target = np.zeros((workers, n_actions), np.float32)
        self.left = np.zeros(workers, int)  # steps until the next target

    def reset(self, worker: int) -> None:
        self.offset[worker] = self.target[worker] = 0.0
        self.left[worker] = 0

    def act(self, obs: np.ndarray, infos: list[dict], steps: np.ndarray) -> np.ndarray:
        actions = []
        for i, info in enumerate(infos):
            record = self.replay.get(info["weather"])
            if record is None:  # a weather whose built-in controls did not finish: the nearest recorded one
                record = next(iter(self.replay.values()))
            step = int(steps[i])
            if self.step_minutes and "time" in info:
                t = info["time"]
                step = ((t.timetuple().tm_yday - 1) * 1440 + t.hour * 60 + t.minute) // self.step_minutes
            base = record[min(step, len(record) - 1)]
            temps = obs[i, self.temperatures]
            if np.any((temps < self.band[0] - 2) | (temps > self.band[1] + 2)):  # the rail: halfway back, and stay
                self.offset[i] *= 0.5
                self.target[i], self.left[i] = self.offset[i], max(self.left[i], 4)
            elif self.left[i] <= 0:  # a new target: any action within `limit` of the record, uniformly
                low, high = np.maximum(base - self.limit, -1.0), np.minimum(base + self.limit, 1.0)
                self.target[i] = self.rng.uniform(low, high) - base
                self.left[i] = self.rng.integers(4, self.hold + 1)
            self.left[i] -= 1
            move = np.clip(self.target[i] - self.offset[i], -self.increment, self.increment)
            self.offset[i] += move
            actions.append(np.clip(base + self.offset[i], -1, 1))
        return np.array(actions, np.float32)
