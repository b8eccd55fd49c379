"""A portfolio's buildings on a Ray cluster (`optimize --ray ADDRESS`): one Ray task per building, each reserving the
building's `--workers` cores, so the cluster runs as many buildings at once as its cores hold, and a user with a
hundred buildings uses a cluster, not a loop.

Each task runs the same stages as the local loop (pipeline.py), in the same folder, DIR/<name>/: DIR must be a folder
every node sees at the same path (docs/cluster.md), as a sweep's runs folder is. A rerun of the same command continues
each building where it stopped, on whichever node takes it. Ctrl-C cancels every task: each stops its running stage as
a local Ctrl-C does (the stage keeps its checkpoint), and the driver waits for them before it ends a Ray it started.
"""

from __future__ import annotations

import contextlib
import logging
import os
from dataclasses import replace

from parallel_eplus.optimize.folders import BuildingFolder
from parallel_eplus.optimize.pipeline import not_finished, optimize_building
from parallel_eplus.optimize.settings import OptimizeSettings

log = logging.getLogger(__name__)

CANCEL_WAIT_S = 960.0  # a cancelled task's stage saving its checkpoint (command.STOP_WAIT_S) and a margin


def _optimize_one(folder: BuildingFolder, settings: OptimizeSettings) -> dict:
    """The Ray task: one building's stages on the node that took it (no progress bar: its log lines reach the
    driver)."""
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    return optimize_building(folder, settings, show=False)


def optimize_on_ray(
    folders: list[BuildingFolder], settings: OptimizeSettings, address: str, rows: list[dict | None]
) -> list[dict | None]:
    """Every building as a Ray task on the cluster at `address` ("local": a Ray of this machine's cores); their
    answers into `rows` in `folders`' order as each ends (so a Ctrl-C leaves those finished), a building that
    failed as a row saying why (the loop's rows, portfolio.py)."""
    import ray
    from ray.exceptions import RayTaskError, TaskCancelledError

    from parallel_eplus.envs.ray_session import connect

    started = connect(None if address == "local" else address, num_cpus=os.cpu_count() or 1)
    try:
        cores = int(ray.cluster_resources().get("CPU", 0))
        workers = min(settings.workers, cores) if cores else settings.workers
        if workers < settings.workers:
            log.warning("--workers %d: the cluster's largest offer is %d cores; each building gets %d",
                        settings.workers, cores, workers)  # fmt: skip
        task = ray.remote(num_cpus=workers, max_retries=0)(_optimize_one)
        each = replace(settings, workers=workers)
        refs = {task.remote(folder, each): i for i, folder in enumerate(folders)}
        log.info("Ray: %d buildings placed, %d cores each (the cluster has %d)", len(folders), workers, cores)
        pending = list(refs)
        try:
            while pending:
                done, pending = ray.wait(pending, num_returns=1)
                i = refs[done[0]]
                try:
                    rows[i] = ray.get(done[0])
                except RayTaskError as e:
                    cause = e.cause if isinstance(e.cause, Exception) else e
                    log.error("%s: %s", folders[i].name, cause)
                    rows[i] = not_finished(folders[i], str(cause))
                log.info("%d of %d buildings done", len(folders) - len(pending), len(folders))
        except KeyboardInterrupt:
            log.warning("interrupted: stopping %d buildings' stages (each keeps what it finished); rerun the same "
                        "command to continue", len(pending))  # fmt: skip
            for ref in pending:
                ray.cancel(ref)
            for ref in pending:
                with contextlib.suppress(TaskCancelledError, RayTaskError, ray.exceptions.GetTimeoutError):
                    ray.get(ref, timeout=CANCEL_WAIT_S)
            raise
        return rows
    finally:
        if started:
            ray.shutdown()
