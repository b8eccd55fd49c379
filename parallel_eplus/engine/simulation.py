"""One episode after another on one worker: the unit the env and the vector env step.

`Simulation` owns everything per step that must not be written twice: action checks and scaling, observation
clipping, the step record and the error messages; what a step is worth (reward, comfort cost) is
`scoring.StepScorer`. Where an episode comes from (a prepared one or a cold start) is `supply.EpisodeSupply`; the
EnergyPlus process itself (spawn, deadlines, exit) is `process.EnergyPlusProcess`. `EnergyPlusEnv` drives one
Simulation; the vector env drives several, writing every action before reading any observation.
"""

from __future__ import annotations

import logging
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np

from parallel_eplus.buildings.building import Building
from parallel_eplus.buildings.weather.files import weather_label
from parallel_eplus.buildings.weather.forecast_features import Forecaster
from parallel_eplus.engine.actions import ActionMap
from parallel_eplus.engine.config import SimulationConfig
from parallel_eplus.engine.episode import EpisodePlan, StepRecorder, err_tail, write_records
from parallel_eplus.engine.episodes.prepared import PreparedEpisode
from parallel_eplus.engine.episodes.process import EnergyPlusProcess, wait_any
from parallel_eplus.engine.episodes.supply import EpisodeSupply
from parallel_eplus.engine.eplus_side import native
from parallel_eplus.engine.observation import Observer
from parallel_eplus.engine.pipes import frames
from parallel_eplus.engine.pipes.at_exit import close_at_exit
from parallel_eplus.engine.scoring import StepScorer
from parallel_eplus.engine.setup import WorkerSetup
from parallel_eplus.errors import EnergyPlusError, ProtocolError

log = logging.getLogger(__name__)


class Simulation:
    """Spawns, steps and stops EnergyPlus processes for consecutive episodes."""

    def __init__(
        self,
        config: SimulationConfig,
        weathers: list[str] | None = None,
        name: str = "0",
        siblings: int = 1,
        prepare: bool = False,
        building: Building | None = None,
    ):
        """`siblings`: how many Simulations one process steps together (sets the default spin). `prepare`: episode
        after episode (an env's): two long-lived EnergyPlus-side processes take turns, one running an episode
        while the other prepares the next (prepared.py, warm_process.py); off for one episode (an evaluation's).
        `building`: the config's, as the command resolved it (None: resolved from the config)."""
        self.config = config
        self._from_prepared = False  # the running episode was prepared ahead (a failed start-up is retried cold)
        self.name = name
        s = self.setup = WorkerSetup.resolve(config, weathers, building)  # every check before anything is spawned
        self.building, self.model, self.comfort, self.idf = s.building, s.model, s.comfort, s.idf
        self.elements, self.observer, self.sensor_names = s.elements, Observer(s), s.building.sensor_names
        self.noise, self.forecasts = s.noise, s.forecasts
        self.scorer = StepScorer(s.comfort, config.reward, config.comfort_margin_c)
        self.weathers, self.weather_paths, self.steps_per_episode = s.weathers, s.weather_paths, s.steps_per_episode
        self.low, self.high = tuple(e.low for e in s.elements), tuple(e.high for e in s.elements)
        self.initial_action, self.policy_names = s.initial_action, s.policy_names
        self.actions = ActionMap(s)  # what an action means: physical values, or corrections (residual control)
        self._forecaster: Forecaster | None = None
        self.weather_params: dict = {}  # this episode's seed and noise parameters, for its records
        self.weather_file: str | None = None  # with weather noise: the episode's perturbed .epw (info["weather_file"])
        self._tmp = None
        if config.output_dir is None:
            self._tmp = tempfile.mkdtemp(prefix="parallel-eplus-episodes-")
        # absolute: forked episodes run in their template's working directory (a relative one named nothing there)
        self.output_dir = Path(config.output_dir or self._tmp).absolute()
        self.output_dir.mkdir(parents=True, exist_ok=True)
        self.action_names = tuple(e.name for e in self.elements)
        self._info: dict = {}
        self._sensed: list[float] = []  # the last observation's sensor values, for its step record
        self.episode = 0
        self.episode_dir: Path | None = None
        self.weather = self.weathers[0]
        self.weather_index = 0
        self.plan: EpisodePlan | None = None
        bridge = native.bridge_library() if config.native_bridge else None
        weather = lambda plan, folder, number: s.episode_weather(plan, folder, number, name)  # noqa: E731
        self.supply = EpisodeSupply(config, s, self.output_dir, weather, prepare, bridge, siblings)
        self._prepare_due = False  # the next is prepared at the first action after the spare is free (reset first)
        self.records: StepRecorder | None = None
        self.last_summary: dict | None = None
        self._area: float | None = None  # the model's floor area (m²), for the per-m² figures
        self._action = self.initial_action.tolist()
        self._closed = False
        close_at_exit(self)

    # -- the process (the vector env's `wait_any` watches `sim.process`) ----------------------
    @property
    def process(self) -> EnergyPlusProcess:
        """The running episode's EnergyPlus process."""
        return self.supply.process

    @property
    def prepared(self) -> PreparedEpisode | None:
        """The next episode, started before the reset that asks for it (None: none yet)."""
        return self.supply.prepared

    @property
    def proc(self):
        return self.process.proc

    def running(self) -> bool:
        """Whether this episode's EnergyPlus process is alive (it exits on its own only after its last step)."""
        return self.process.running()

    # -- episode lifecycle --------------------------------------------------------------------
    def start(self, weather_index: int | None = None, plan: EpisodePlan | None = None) -> tuple[np.ndarray, dict]:
        """Stop any running process, start the next episode and return observation 0."""
        self.launch(weather_index, plan)
        return self.first_observation()

    def next_plan(self, weather_index: int | None = None, seed: int | None = None, options: dict | None = None):
        """The next episode's plan: weathers cycle episode by episode unless `weather_index` picks one. `seed`: the
        episode's weather noise and forecast error (None: drawn from the config's seed, this worker's name and the
        episode's number, when its directory is claimed)."""
        i = self.episode % len(self.weathers) if weather_index is None else weather_index
        start = self.setup.start_day(self.name, self.episode + 1) if self.config.random_start else None
        return EpisodePlan(i, self.weathers[i], self.weather_paths[i], seed, EpisodePlan.options_key(options), start)

    def launch(self, weather_index: int | None = None, plan: EpisodePlan | None = None) -> None:
        """Start the next episode without waiting for its first observation (the vector env starts many at once):
        the prepared one if it was prepared for `plan` and is alive, else a new process. The one after it starts
        preparing here if this one was prepared but is not parked yet, else at its first action (`send`)."""
        if not self.supply.over():  # else it is over, its files being finished
            self.stop()
        plan = plan or self.next_plan(weather_index)
        ready = self.supply.take(plan)
        self._from_prepared = ready is not None
        if ready is not None:
            self.episode_dir, (self.weather_params, self._forecaster) = ready.episode_dir, ready.weather
        else:
            self.episode_dir, (self.weather_params, self._forecaster) = self.supply.start(plan)
        self.process.attach()  # a forked one's pid watched
        self.supply.warm_spare()
        self.plan = plan
        self.weather_index, self.weather = plan.weather_index, plan.weather
        # a perturbed year is the episode's own file: a planner's forecast must read it, not the named weather's
        self.weather_file = str(self.episode_dir / plan.epw.name) if self.noise is not None else None
        self.episode += 1
        self.records = StepRecorder(self.action_names, self.sensor_names)
        self._action = self.initial_action.tolist()
        self.last_summary = None
        self.actions.start()  # a fresh rule-based controller (integral state) per episode, where one is corrected
        self.scorer.start()  # the month's running peaks start at 0 each episode
        if self._from_prepared and not self.process.has_frame():
            self.prepare()  # it is still warming up and the spare is idle: the next starts now (back-to-back short
            # episodes); else at this episode's first action, so a reset that finds it parked returns at once, and a
            # cold start (its spare process still starting up too) gets the cores to itself

    def prepare(self, plan: EpisodePlan | None = None) -> None:
        """Start the next episode (`plan`, default: the rotation's next) in the spare process, to be swapped in
        by the `launch` that asks for the same plan."""
        if self.supply.prepared is None and not self._closed:
            self.supply.prepare(plan or self.next_plan())

    def first_observation(self) -> tuple[np.ndarray, dict]:
        """Wait through sizing and warmup for observation 0 of the launched episode.

        A prepared episode that fails before its first observation is replaced by a cold start of the same plan
        (the cold one's failure is the episode's)."""
        try:
            code, values = self._recv("the first observation", self.config.start_timeout_s)
        except EnergyPlusError:
            if not self._from_prepared:
                raise
            log.warning("the prepared episode failed to start (%s); starting it afresh", self.episode_dir)
            self.episode -= 1  # the same episode again: the weather rotation does not move on
            self.launch(plan=self.plan)
            code, values = self._recv("the first observation", self.config.start_timeout_s)
        if code != frames.DATA:
            raise self._error(f"EnergyPlus sent control frame {code} instead of the first observation")
        obs, info = self._observation(values)
        self._prepare_due = self.supply.prepare_next and self.prepared is None
        return obs, info

    def send(self, action) -> None:
        """Check, clip, scale and send one action; its observation is read by `receive`."""
        if self.proc is None or self.supply.over():  # over, not reset
            raise RuntimeError("no simulation running: call reset() first")
        if self._prepare_due and not self.supply.spare_busy():
            self._prepare_due = False  # once the spare has finished the episode before: a step never waits for it
            self.prepare()
        self._action = self.actions.frame(action, self._info)
        try:
            self.process.send(frames.encode(self._action), self.config.step_timeout_s)
        except BrokenPipeError as e:  # pragma: no cover - the FIFO is held open by us
            raise self._error(f"cannot send the action: {e}") from e

    def receive(self) -> tuple[np.ndarray, float, bool, dict]:
        """(observation, reward, terminated, info) for the action last sent, due `step_timeout_s` after it."""
        code, values = self._recv("an observation", self.config.step_timeout_s)
        obs, info = self._observation(values)
        r, parts, applies = self.scorer(info)
        acted = self.actions.applied(self._action, info)
        self.records.add(info["time"], (*self._sensed, *acted, r, *parts.values(), float(applies)))
        terminated = code == frames.END
        if terminated:
            self._finish()
            info["episode_summary"] = self.last_summary
            info["episode_dir"] = str(self.episode_dir)
        return obs, r, terminated, info

    # -- internals ----------------------------------------------------------------------------
    def _observation(self, values: np.ndarray) -> tuple[np.ndarray, dict]:
        if len(values) != self.observer.width:
            raise self._error(f"observation frame has {len(values)} values", ProtocolError)
        obs, self._info, self._sensed = self.observer(values, self.weather, self._forecaster)
        if self.weather_file is not None:
            self._info["weather_file"] = self.weather_file
        return obs, self._info

    def _recv(self, what: str, limit_s: float) -> tuple[int, np.ndarray]:
        """The frame awaited next, by the process's deadline (set `limit_s` after the launch or the action)."""
        try:
            code, values = self.process.recv()
        except TimeoutError as e:
            raise self._error(f"EnergyPlus sent no {what} within {limit_s:.0f} s (hung?)") from e
        except ChildProcessError as e:
            raise self._error(f"EnergyPlus died while we waited for {what}: {e}") from e
        except ProtocolError as e:
            raise self._error(f"malformed frame from EnergyPlus: {e}", ProtocolError) from e
        if code == frames.ERROR:
            raise self._error(f"EnergyPlus failed (status {values[0] if len(values) else '?'})")
        return code, values

    def _error(self, message: str, kind: type[EnergyPlusError] = EnergyPlusError) -> EnergyPlusError:
        """Stop the process first, so the error file is complete and nothing is left running (a prepared episode
        and an idle warm process neither: whoever handles the error starts afresh)."""
        self.supply.abort()
        if self.records is not None and not self.records.n:
            self.records = None  # keep the failed episode's directory for the user to inspect
        return kind(f"[{weather_label(self.weather)}] {message}", self.episode_dir, err_tail(self.episode_dir))

    def _finish(self) -> None:
        """The run period is over: write the records while EnergyPlus finishes its own files. A long-lived process
        is waited for when it is needed again (`EpisodeSupply.settle`), not here: the env's loop goes on meanwhile
        (~10-20 ms an episode of EnergyPlus's end-of-run files and `delete_state`)."""
        try:
            self._write_records(complete=True, prune=False)
        finally:
            self.supply.end(self.episode_dir)
            if not self.supply.prepare_next:  # a process per episode: wait for it now, as an evaluation expects
                self.supply.settle()

    def _write_records(self, complete: bool, prune: bool = True) -> None:
        if self.records is None or self.episode_dir is None:
            return
        extra = {"episode": self.episode, "worker": self.name, "weather": weather_label(self.weather),
                 "complete": complete, **self.weather_params}  # fmt: skip
        if self.plan is not None and self.plan.start_day is not None:  # random_start: the day drawn
            extra["start_day"] = self.plan.start_day
        steps = self.records.frame()
        scored = self.setup.scored_steps(steps, extra)
        table = not (complete and self.config.keep_episodes == 0)  # pruned at once: ~8 ms an episode saved
        self.last_summary = write_records(self.episode_dir, steps, extra, self.comfort, scored, table, self._area)
        self._area = self.last_summary.get("floor_area_m2")  # the same model every episode: its eio read once
        self.records = None
        if prune:
            self.supply.prune(self.episode_dir)

    def stop(self) -> None:
        """End a running episode early (EnergyPlus stopped, its long-lived process kept) and keep the partial
        record."""
        if self.proc is not None:
            self.process.end_episode()
        if self.records is not None:
            if self.records.n:
                self._write_records(complete=False)
            elif self.episode_dir is not None:  # started but never stepped: nothing worth keeping
                shutil.rmtree(self.episode_dir, ignore_errors=True)
        self.records = None

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        self.supply.stop_all()  # the last episode's files whole, then every process killed
        self.stop()  # the running episode's partial record
        self.supply.close()
        if self._tmp is not None:
            shutil.rmtree(self._tmp, ignore_errors=True)

    def __del__(self):
        if not getattr(self, "_closed", True) and not sys.is_finalizing():
            self.close()


__all__ = ["Simulation", "wait_any"]
