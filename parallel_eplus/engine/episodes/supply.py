"""Where a worker's episodes come from (issue 39): its EnergyPlus processes, the next episode prepared beside the
running one, and the episode past its last step.

A worker has two EnergyPlus processes that take turns: one runs the episode, the spare prepares the next (a
long-lived process, warm_process.py, or a fork of a template parked at the first control step, fork.py). An
episode is asked for by its plan: the prepared one if it was prepared for that plan and is alive, else a cold
start. An episode over is not waited for at its last step but when its process is needed again (`settle`).
`Simulation` steps the episode; this decides how it started.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

from parallel_eplus.buildings.idf.takeover import NODE_SETPOINT, taken_setpoints
from parallel_eplus.engine.config import SimulationConfig
from parallel_eplus.engine.episode import MODEL_FILE, EpisodePlan, prune_episodes
from parallel_eplus.engine.episodes.fork import Template, Templates
from parallel_eplus.engine.episodes.prepared import EpisodeStarter, PreparedEpisode
from parallel_eplus.engine.episodes.process import EnergyPlusProcess
from parallel_eplus.engine.setup import WorkerSetup

log = logging.getLogger(__name__)


class EpisodeSupply:
    """A worker's EnergyPlus processes and the episodes started in them, numbered in the order they began."""

    def __init__(
        self,
        config: SimulationConfig,
        setup: WorkerSetup,
        output_dir: Path,
        weather: Callable[[EpisodePlan, Path, int], tuple[Path, Any]],
        prepare: bool,
        bridge: str | None,
        siblings: int,
    ):
        """`weather(plan, episode_dir, number)`: writes an episode's weather file (EpisodeStarter.start). `prepare`:
        the next episode is prepared in the spare process while one runs; off for one episode (an evaluation's)."""
        self.config = config
        self.prepare_next = prepare
        self.process = EnergyPlusProcess(config.spin_s, bridge, siblings=siblings, warm=prepare)
        self.spare = EnergyPlusProcess(config.spin_s, bridge, siblings=siblings, warm=prepare)
        self.prepared: PreparedEpisode | None = None
        self.number = 0  # the last episode directory's number (its folder may be shared)
        self.ended: tuple[EnergyPlusProcess, Path | None] | None = None  # an episode past its last step (`settle`)
        self._whole: list[Path] = []  # this worker's own episode directories still whole, oldest first
        self._weather = weather
        taken = taken_setpoints(_commanded(setup))
        self._starter = EpisodeStarter(output_dir, setup.idf, config, setup.process_args(), taken,
                                       setup.demand_ventilation)  # fmt: skip
        # Episodes forked from a template parked at their first control step (fork.py): not with weather noise (a
        # new weather file each episode) or random starts (a new run period), nor for one episode (an evaluation's)
        forks = prepare and config.fork_episodes and setup.noise is None and not config.random_start
        native_arg = ["--native", bridge] if bridge else []
        self.templates = Templates(self._starter.model, MODEL_FILE, [*setup.process_args(), *native_arg],
                                   config.start_timeout_s) if forks else None  # fmt: skip
        self._closed = False

    def take(self, plan: EpisodePlan) -> PreparedEpisode | None:
        """The prepared episode, now the running process's, if it was prepared for `plan` and is alive; else None
        (a prepared one that does not fit or died is discarded)."""
        ready, self.prepared = self.prepared, None
        if ready is not None and (ready.plan != plan or not ready.usable(self.config.start_timeout_s)):
            ready.discard()
            ready = None
        if ready is not None:  # swap it in; the finished episode's process (and pipes) prepare the one after
            self.process, self.spare = ready.process, self.process
        return ready

    def start(self, plan: EpisodePlan) -> tuple[Path, Any]:
        """Start `plan`'s episode cold in the running process: (its directory, what its weather came with)."""
        self.settle()  # the process may still finish the last episode's files
        template = self._template(plan, wait=True)
        if self.prepare_next and template is None:  # its Python start-up runs while the model is written
            self.process.warm_up()
        episode_dir, self.number, weather = self._starter.start(plan, self.process, self.number + 1, self._weather,
                                                                template)  # fmt: skip
        return episode_dir, weather

    def prepare(self, plan: EpisodePlan) -> None:
        """Start `plan`'s episode in the spare process, to be handed out by the `take` that asks for the same plan."""
        if self.prepared is not None or self._closed:
            return
        self.settle()  # the spare may still finish the episode before (a few ms, long over in training)
        self.spare.kill()
        template = self._template(plan, wait=False)  # not parked yet: this one starts in the spare process
        episode_dir, number, weather = self._starter.start(plan, self.spare, self.number + 1, self._weather,
                                                           template, wait=False)  # fmt: skip
        self.number = number  # numbers follow the order episodes began in
        self.prepared = PreparedEpisode(plan, self.spare, episode_dir, number, weather)

    def warm_spare(self) -> None:
        """The first episode's spare long-lived process starts up beside it (none where episodes are forked)."""
        if self.prepare_next and self.templates is None:
            self.spare.warm_up()

    def _template(self, plan: EpisodePlan, wait: bool) -> Template | None:
        """The parked template to fork `plan`'s episode from (fork.py), or None: none for this worker, or none
        parked (without `wait`) or able to park."""
        if self.templates is None:
            return None
        return self.templates.get(plan.epw, self.process.pipe_dir(), wait)

    def discard_prepared(self) -> None:
        if self.prepared is not None:
            self.prepared.discard()
            self.prepared = None

    def end(self, episode_dir: Path | None) -> None:
        """The running episode is past its last step: its process finishes its files while the env goes on."""
        self.ended = (self.process, episode_dir)

    def over(self) -> bool:
        """The running process's episode is past its last step (and no new one started in it)."""
        return self.ended is not None and self.ended[0] is self.process

    def spare_busy(self) -> bool:
        """The spare still finishes the episode before: preparing in it now would wait."""
        return self.ended is not None and self.ended[0].running()

    def settle(self) -> None:
        """Wait for the episode past its last step to finish (EnergyPlus's files written, its state freed), then
        prune: older episodes are pruned after, so nothing is removed under a writing EnergyPlus."""
        if self.ended is None:
            return
        (process, episode_dir), self.ended = self.ended, None
        process.finish()
        if episode_dir is not None:
            self.prune(episode_dir)

    def prune(self, episode_dir: Path) -> None:
        """Keep the newest `keep_episodes` of this worker's episode directories whole."""
        self._whole = prune_episodes([*self._whole, episode_dir], self.config.keep_episodes)

    def abort(self) -> None:
        """After a failure: nothing left running (a prepared episode, the templates, an idle spare): whoever
        handles the error starts afresh."""
        self.settle()
        self.process.kill()
        self.discard_prepared()
        if self.templates is not None:
            self.templates.close()
        self.spare.close()

    def stop_all(self) -> None:
        """Kill the running episode's process (no need to stop EnergyPlus gracefully), the spare and a prepared
        episode, after the last episode's files are whole."""
        self._closed = True
        self.settle()
        self.process.kill()
        self.spare.kill()
        self.discard_prepared()

    def close(self) -> None:
        """End every process and remove every pipe (after `stop_all`)."""
        self.stop_all()
        if self.templates is not None:
            self.templates.close()
        self.process.close()
        self.spare.close()


def _commanded(setup: WorkerSetup) -> tuple:
    """The actions whose nodes the copy takes from the model's setpoint managers (buildings/idf/takeover.py): every one,
    or under `relinquish` the nodes a scheduled manager sets, whose schedule the bridge writes when released. A
    node's other managers stay for a released node to fall back to; one the agent commands is then written after
    them at each apply point, too late for the managers that follow it (a `SetpointManager:MixedAir` reads its
    reference node before: the medium office's coils kept 12.8 C under a commanded 18)."""
    if not setup.config.relinquish:
        return setup.elements
    taken = tuple(replace(e, actuators=tuple(a for a, o in zip(e.actuators, plans, strict=True) if o))
                  for e, plans in zip(setup.elements, setup.building.node_schedules, strict=True))  # fmt: skip
    keys = {a.key for e in taken for a in e.actuators}
    kept = [a.key for e in setup.elements for a in e.actuators
            if a.component_type.lower() == NODE_SETPOINT and a.key not in keys]  # fmt: skip
    if kept:
        log.warning(
            "relinquish: %s keep the model's own setpoint managers (none a SetpointManager:Scheduled whose "
            "schedule a released node could get back); a value commanded there is written after them and may "
            "not reach the managers that follow the node",
            ", ".join(kept),
        )
    return taken
