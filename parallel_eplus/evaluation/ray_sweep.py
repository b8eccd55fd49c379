"""`evaluate --backend ray`: each (controller, weather) episode is one Ray task, wherever a CPU is free.

An evaluation job is a whole episode, so it needs no call per step either: a policy's files (a few
kB to a few hundred kB) go into Ray's object store once and every task that runs it reads them there;
a task returns its episode's summary and the files the figures read (`steps.parquet`, `summary.json`,
the EnergyPlus error file), which land in the same episode folders a local sweep writes. Nothing has
to be on the nodes but the package (docs/cluster.md).
"""

from __future__ import annotations

import logging
import tempfile
import time
from dataclasses import replace
from pathlib import Path

from parallel_eplus import io
from parallel_eplus.engine.config import SimulationConfig
from parallel_eplus.engine.episode import claim_episode_dir
from parallel_eplus.envs.ray_session import connect
from parallel_eplus.errors import EnergyPlusError
from parallel_eplus.evaluation.controllers import failure_row

log = logging.getLogger(__name__)

RETURNED_FILES = ("steps.parquet", "summary.json", "eplusout.err")
PROGRESS_STEPS = 1000  # a task reports its steps this often, so the bar moves within a year-long episode
POLL_S = 5.0  # how often the driver reads them


class _Steps:
    """The steps each running episode has taken, as its task reports them (a Ray actor the tasks share)."""

    def __init__(self):
        self.steps: dict[int, int] = {}

    def add(self, key: int, n: int) -> None:
        self.steps[key] = self.steps.get(key, 0) + n

    def read(self) -> dict[int, int]:
        return self.steps


def _policy_files(model_zip: Path) -> dict[str, bytes]:
    """A policy's model and statistics, by the names `load_policy` looks for beside each other."""
    from parallel_eplus.runs.policy_files import MODEL_FILE, NORMALIZE_FILE, normalization_file

    stats = normalization_file(model_zip)
    return {MODEL_FILE: model_zip.read_bytes(), Path(NORMALIZE_FILE).with_suffix(stats.suffix).name: stats.read_bytes()}


def _episode(controller, cfg: SimulationConfig, files: dict[str, bytes] | None, progress=None,
             key: int = 0) -> tuple[dict, dict[str, bytes]]:  # fmt: skip
    """One whole episode on a node; returns (its results row, the files the figures read). `progress`: the
    driver's `_Steps`, told every PROGRESS_STEPS steps."""
    from parallel_eplus.engine.pipes.leftovers import write_owner
    from parallel_eplus.engine.simulation import Simulation

    with tempfile.TemporaryDirectory(prefix="parallel-eplus-eval-") as tmp:
        write_owner(Path(tmp))  # a worker killed outright leaves it: `clean` and the next run's sweep remove it
        if files is not None:  # the policy, written where this node can read it
            for name, data in files.items():
                (Path(tmp) / name).write_bytes(data)
            controller = replace(controller, path=Path(tmp) / "model.zip")
        sim = Simulation(replace(cfg, output_dir=str(Path(tmp) / "episodes")), name=controller.label)
        act = controller.make(cfg.building)
        try:
            sim.launch()
            obs, info = sim.first_observation()
            terminated, steps = False, 0
            while not terminated:
                sim.send(act(obs, info))
                obs, _, terminated, info = sim.receive()
                steps += 1
                if progress is not None and steps % PROGRESS_STEPS == 0:
                    progress.add.remote(key, PROGRESS_STEPS)  # not waited for
        finally:
            sim.close()
        episode_dir = Path(info["episode_dir"])
        out = {n: (episode_dir / n).read_bytes() for n in RETURNED_FILES if (episode_dir / n).is_file()}
        row = {"controller": controller.label, "run": controller.run, **info["episode_summary"]}
        return {**row, "episode_dir": episode_dir.name}, out


def run_jobs(
    jobs: list[tuple], workers: int, address: str | None, bar, deadline_s: float, keep_going: bool = False
) -> tuple[list[dict], list[dict]]:
    """Run (controller, SimulationConfig) jobs as Ray tasks; returns (rows, failures) as the local sweep does.

    `workers`: CPUs of a Ray started here (no `address`); on a cluster, its CPUs decide. `deadline_s`:
    the longest wait for any next episode to finish (each EnergyPlus step has its own deadline too).
    """
    import ray

    owns = connect(address, workers)
    task = ray.remote(num_cpus=1, max_retries=0)(_episode)
    progress = ray.remote(num_cpus=0)(_Steps).remote()
    shipped: dict[Path, object] = {}
    pending: dict = {}
    try:
        for key, (controller, cfg) in enumerate(jobs):
            files = None
            if controller.kind == "policy":
                if controller.path not in shipped:  # once per policy, however many weathers run it
                    shipped[controller.path] = ray.put(_policy_files(controller.path))
                files = shipped[controller.path]
            pending[task.remote(controller, cfg, files, progress, key)] = (controller, cfg, key)
        log.info("Ray evaluation: %d episodes over %.0f CPUs", len(jobs), ray.cluster_resources().get("CPU", 0))
        rows: list[dict] = []
        failures: list[dict] = []
        finished_steps = 0
        t0 = time.monotonic()
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1, timeout=POLL_S)
            if not done:
                if time.monotonic() - t0 > deadline_s:
                    raise TimeoutError(f"no evaluation episode finished within {deadline_s:.0f} s on the Ray cluster")
                running = {k for _, _, k in pending.values()}
                steps = ray.get(progress.read.remote(), timeout=60)
                bar.update(max(0, finished_steps + sum(n for k, n in steps.items() if k in running) - bar.n))
                continue
            controller, cfg, _ = pending.pop(done[0])
            t0 = time.monotonic()  # the deadline is for the next episode to end, a failed one's too
            try:
                row, files = ray.get(done[0], timeout=60)
            except EnergyPlusError as e:  # Ray's task error is also the task's own exception type
                if not keep_going:
                    raise
                failures.append(failure_row(controller, cfg, e))
                continue
            # where a local sweep would have written it: its own folder, beside any earlier sweep's
            local, _ = claim_episode_dir(Path(cfg.output_dir), row["episode_dir"].split("-", 2)[2])
            for name, data in files.items():
                io.write_bytes(local / name, data)
            row["episode_dir"] = str(local)
            rows.append(row)
            finished_steps += int(row.get("steps", 0))
            bar.update(max(0, finished_steps - bar.n))  # the running episodes' steps: at the next poll
            bar.set_postfix(done=len(rows), last=f"{controller.label} {row['weather']}")
            log.debug("%s %s done", controller.label, row["weather"])
        return rows, failures
    finally:
        for ref in pending:  # failed or interrupted: stop what still runs (its EnergyPlus sees its pipes close)
            ray.cancel(ref, force=True)
        if owns:
            ray.shutdown()
            if pending:  # its workers were killed outright: their episodes' folders are this run's to remove
                from parallel_eplus.engine.pipes.leftovers import sweep

                sweep()
