"""The next episode, decided and started before `reset()` asks for it (issue 39).

While an episode runs, its worker prepares the next: the episode's directory and model are written and its
EnergyPlus process reads its inputs, sizes, warms up and parks at its first control step (in a long-lived process,
warm_process.py; or forked from a template parked there, fork.py), its observation 0 written and its first action
awaited. `reset()` swaps it in if it was prepared for what
the reset asks (the same `EpisodePlan`); otherwise, or if it died or hung meanwhile, it is discarded (killed, its
directory removed) and the episode starts cold. Nothing in EnergyPlus sees the difference: the same files, the
same arguments, the same process code, so a prepared episode equals a cold one bit for bit
(tests/test_prepared.py).
"""

from __future__ import annotations

import logging
import shutil
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from parallel_eplus.buildings.idf.prepare import prepare_idf
from parallel_eplus.buildings.weather.files import weather_label
from parallel_eplus.engine.config import SimulationConfig
from parallel_eplus.engine.episode import MODEL_FILE, EpisodePlan, claim_episode_dir
from parallel_eplus.engine.episodes.fork import ForkFailed, Template
from parallel_eplus.engine.episodes.process import EnergyPlusProcess

log = logging.getLogger(__name__)
STOP_GRACE_S = 5.0  # for a discarded parked episode to stop before its process is killed
MODELS_KEPT = 4  # prepared models kept per worker, one per first day (`random_start` draws a day an episode)


class EpisodeStarter:
    """Writes an episode's directory (its model, its weather) and starts its EnergyPlus: one code path for a cold
    start and a prepared one, which is why they are the same episode."""

    def __init__(
        self,
        output_dir: Path,
        idf: Path,
        config: SimulationConfig,
        args: list[str],
        takeover: tuple = (),
        ventilation: bool = False,
    ) -> None:
        """`args`: the EnergyPlus side's arguments every episode shares (model, steps, initial action); `takeover`:
        the node setpoints the actions own, taken from the model's managers (buildings/idf/takeover.py); `ventilation`:
        the outdoor air on demand (buildings/idf/ventilation.py)."""
        self.output_dir, self.idf, self.config, self.args = output_dir, idf, config, args
        self.takeover, self.ventilation = takeover, ventilation
        self._models: dict[int, bytes] = {}  # the episode's model (idf_prep.py) per first day of the run

    def model(self, path: Path | None = None, start_day: int | None = None) -> bytes:
        """The episode's model (tokenized once per first day, ~20 ms; else the same for every episode), written to
        `path` if given. `start_day`: the run's first day of the year (None: the config's)."""
        cfg = self.config
        day = cfg.start_day if start_day is None else start_day
        model = self._models.get(day)
        if model is None:
            if len(self._models) >= MODELS_KEPT:  # random starts: a model per day drawn, not a year of them in memory
                self._models.pop(next(iter(self._models)))
            with tempfile.TemporaryDirectory(prefix="parallel-eplus-model-") as tmp:
                made = Path(tmp) / MODEL_FILE
                report = prepare_idf(self.idf, made, cfg.run_days, cfg.energyplus_csv, cfg.extra_outputs,
                                     day, cfg.start_weekday, self.takeover, self.ventilation)  # fmt: skip
                model = self._models[day] = made.read_bytes()
            if not cfg.random_start or len(self._models) == 1:  # the same report for every start day
                for line in report.lines():
                    log.info("prepared model %s: %s", self.idf.name, line)
        if path is not None:
            path.write_bytes(model)
        return model

    def start(
        self,
        plan: EpisodePlan,
        process: EnergyPlusProcess,
        number: int,
        weather: Callable[..., tuple[Path, Any]],
        template: Template | None = None,
        wait: bool = True,
    ) -> tuple[Path, int, Any]:
        """Claim the episode's directory (numbered `number` or above), write its files, start its EnergyPlus in
        `process` without waiting: (the directory, its number, what `weather` made beside the weather file).
        With a parked `template` of its weather (fork.py), the episode is forked from it (without `wait`, its pid
        is taken when it is handed out: `EnergyPlusProcess.attach`); if the template failed, it is closed and the
        episode starts as without one.

        `weather(plan, episode_dir, number)` writes the episode's weather file into its directory (a link, or a
        perturbed copy: the noise is drawn here, when the episode is prepared) and returns (its path, extras)."""
        episode_dir, number = claim_episode_dir(self.output_dir, weather_label(plan.weather), number)
        cfg, model, log_path = self.config, episode_dir / MODEL_FILE, episode_dir / "energyplus.log"
        try:
            self.model(model, plan.start_day)
            epw, extras = weather(plan, episode_dir, number)
            if template is not None:
                try:
                    process.fork(template, episode_dir, log_path, cfg.start_timeout_s, wait)
                    return episode_dir, number, extras
                except ForkFailed as e:
                    log.warning("%s; starting the episode without it", e)
                    template.close()
            args = ["--idf", str(model), "--epw", str(epw), "--output-dir", str(episode_dir)]
            process.spawn([*args, *self.args], log_path, cfg.start_timeout_s)
        except BaseException:
            shutil.rmtree(episode_dir, ignore_errors=True)
            raise
        return episode_dir, number, extras


@dataclass
class PreparedEpisode:
    """A started episode not yet handed out: its plan, its process and the directory it writes to."""

    plan: EpisodePlan
    process: EnergyPlusProcess
    episode_dir: Path
    number: int
    weather: Any = None  # what the episode's weather file came with (noise parameters, forecasts)
    started_at: float = field(default_factory=time.monotonic)

    def parked(self) -> bool:
        """Observation 0 is written: EnergyPlus waits at its first control step."""
        return self.process.has_frame()

    def usable(self, start_timeout_s: float) -> bool:
        """Alive, and either parked or still within its start-up deadline: a dead or hung one is replaced."""
        if not self.process.running() or _exiting(getattr(self.process.proc, "pid", None)):
            log.warning("the prepared episode's EnergyPlus (%s) died; starting the episode afresh", self.episode_dir)
            return False
        if self.parked():
            self.process.deadline = time.monotonic() + start_timeout_s  # its frame is there: read it now
            return True
        if self.process.deadline <= time.monotonic():
            log.warning("the prepared episode's EnergyPlus (%s) hung in start-up; starting afresh", self.episode_dir)
            return False
        return True  # still warming up: the reset waits for it, as for a cold start, but less

    def discard(self) -> None:
        """End its episode (a parked one in a long-lived process is stopped, the process kept) and remove its
        directory: it never stepped, so nothing in it is worth keeping."""
        if self.parked():
            self.process.end_episode(STOP_GRACE_S)
        self.process.kill()  # what was still starting up
        shutil.rmtree(self.episode_dir, ignore_errors=True)


def _exiting(pid: int | None) -> bool:
    """Killed and still tearing down: its main thread a zombie while its other threads exit. It cannot be reaped
    yet (so it still counts as running) and its observation 0 is still in the pipe, but it will never step."""
    if pid is None:
        return False
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            return f.read().rsplit(b")", 1)[1].split()[0] in (b"Z", b"X")
    except (OSError, IndexError):
        return False
