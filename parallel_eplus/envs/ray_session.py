"""Joining or starting Ray, and how our code reaches the cluster's nodes.

Code travels with the job (Ray's runtime environment), not by "the same checkout at the same path on
every machine": each node needs only the dependencies installed (`scripts/setup.sh`, or
`pip install 'parallel-eplus[train]'`), and a change on the driver reaches every node at the next run, so a
cluster never runs yesterday's code. The package goes as a `py_modules` entry laid out as its wheel is,
the built-in buildings' EnergyPlus models inside it (buildings/resources.py finds them there).
"""

from __future__ import annotations

import logging
import os
import shutil
import tempfile
from pathlib import Path

log = logging.getLogger(__name__)

JOB_ENV = "RAY_JOB_CONFIG_JSON_ENV_VAR"  # set by Ray's job supervisor for a submitted job's driver


def connect(address: str | None, num_cpus: int) -> bool:
    """Join the cluster at `address`, or start a Ray of our own; returns whether we started it (and so end it).

    With no address: `address="local"`, a new Ray whatever an earlier cluster left in Ray's temp folder
    (a stale `ray_current_cluster` file) or in `RAY_ADDRESS`; except in a Ray job (`ray job submit`), whose
    driver joins the cluster that runs the job (its `RAY_ADDRESS`).
    """
    import ray

    if ray.is_initialized():
        return False
    if not address and JOB_ENV in os.environ and os.environ.get("RAY_ADDRESS"):
        address = os.environ["RAY_ADDRESS"]
        log.info("Ray: running as a Ray job; joining its cluster at %s", address)
    if not address:
        # Ray starts its workers at nice 15 (to keep a driver responsive); here the workers are the work: on a
        # machine doing anything else, a year's evaluation at nice 15 got a seventh of a core (2026-11-28)
        os.environ.setdefault("RAY_worker_niceness", "0")
        ray.init(address="local", num_cpus=num_cpus, include_dashboard=False, log_to_driver=True)
        return True
    if os.environ.get("RAY_AUTH_MODE") != "token":
        log.warning(
            "RAY_AUTH_MODE is not 'token': a Ray 2.60 cluster with a token (the default) refuses this driver "
            "until it gives up; export RAY_AUTH_MODE=token RAY_AUTH_TOKEN_PATH=<the cluster's token file>"
        )
    with tempfile.TemporaryDirectory(prefix="parallel-eplus-job-") as staging:
        try:  # the package is uploaded during init; the staging copy is not needed after it
            ray.init(address=address, runtime_env={"py_modules": [str(_stage_package(Path(staging)))]},
                     log_to_driver=True)  # fmt: skip
        except ConnectionError as e:
            raise ConnectionError(
                f"{e}\n  Ray 2.60 clusters check a token: export RAY_AUTH_MODE=token and RAY_AUTH_TOKEN_PATH=<the "
                "cluster's token file> (docs/cluster.md) in this shell too"
            ) from e
    log.info("Ray: joined %s; our package ships with the job (runtime_env py_modules)", address)
    return True


def _stage_package(staging: Path) -> Path:
    """A copy of the package as its wheel lays it out: the built-in EnergyPlus models in buildings/models."""
    import parallel_eplus
    from parallel_eplus.buildings import resources

    package = Path(parallel_eplus.__file__).parent
    target = staging / "parallel_eplus"
    shutil.copytree(package, target, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    models = target / "buildings" / "models"
    models.mkdir(exist_ok=True)
    for folder in reversed(resources.model_dirs()):  # the wheel's own copy wins, as resources.model_file does
        for f in folder.iterdir():
            if f.is_file():
                shutil.copy2(f, models / f.name)
    return target
