"""`--ray ADDRESS`: each running test's simulation in a Ray actor (one CPU), placed by Ray on any node of the
cluster, so the service grows past one machine on the engine it already uses (envs/ray_session.py joins the
cluster with the package shipped). The server keeps each test's metadata; the actor runs its episode. A test's
spec must be readable on the actor's node: the shipped buildings always are (they travel with the package), a
`--specs` folder must be at the same path there.
"""

from __future__ import annotations

import logging

from parallel_eplus.deploy.boptest.test import BoptestTest, TestError

log = logging.getLogger(__name__)


class RemoteTest:
    """A test's methods called on its actor, one at a time; a refusal there is raised here as it was raised."""

    def __init__(self, actor):
        self.actor = actor

    def __getattr__(self, method: str):
        import ray

        def called(*args):
            try:
                return ray.get(getattr(self.actor, method).remote(*args))
            except ray.exceptions.RayTaskError as e:
                cause = getattr(e, "cause", None)
                if isinstance(cause, TestError):
                    raise TestError(cause.status, cause.message) from None
                raise TestError(500, f"the test's Ray actor failed: {e}") from None
            except ray.exceptions.RayActorError as e:
                raise TestError(500, f"the test's Ray actor died: {e}") from None
            except TestError:
                raise
            except ray.exceptions.RayError as e:  # anything else Ray raises: the test's failure, not the server's
                raise TestError(500, f"the test's Ray actor failed: {e}") from None

        return called

    def close(self) -> None:
        import ray

        try:
            ray.get(self.actor.close.remote(), timeout=30)
        except Exception as e:  # noqa: BLE001 - the actor is killed below whatever happened
            log.warning("closing a test's actor: %s", e)
        ray.kill(self.actor)


def ray_tests(address: str, workers: int):
    """Join (or with "local" start) Ray; returns the factory the registry calls for each test that starts running."""
    import ray

    from parallel_eplus.envs.ray_session import connect

    connect(None if address == "local" else address, num_cpus=workers)
    actor_class = ray.remote(num_cpus=1)(BoptestTest)

    def make(entry) -> RemoteTest:
        t = entry.local
        return RemoteTest(actor_class.remote(t.testcase, str(t.building.spec.path), t.weather, t.cache))

    return make
