"""Shared fixtures: every test that needs EnergyPlus runs the real thing on a short run period."""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

import pytest

# Every process this test session starts inherits the marker, so a training run sharing the machine
# is never mistaken for a leak.
os.environ["PARALLEL_EPLUS_TEST_SESSION"] = str(os.getpid())
MARKER = f"PARALLEL_EPLUS_TEST_SESSION={os.getpid()}"

# A temp folder of the session's own, for it and every process it starts: whatever our code leaves in "the
# temp folder" is found there at the end (`pytest_sessionfinish`), whatever else shares /tmp. Ray and pytest's
# own tmp_path stay where they were (Ray's socket paths have a length limit).
_SYSTEM_TMP = os.environ.get("TMPDIR", "/tmp")
os.environ.setdefault("RAY_TMPDIR", _SYSTEM_TMP)
os.environ.setdefault("PYTEST_DEBUG_TEMPROOT", _SYSTEM_TMP)
for _old in Path(_SYSTEM_TMP).glob("pe-tests-*-*"):  # a killed session's folder (its pipes too): its pid is gone
    if _old.name.split("-")[2].isdigit() and not Path(f"/proc/{_old.name.split('-')[2]}").exists():
        shutil.rmtree(_old, ignore_errors=True)
SESSION_TMP = tempfile.mkdtemp(prefix=f"pe-tests-{os.getpid()}-", dir=_SYSTEM_TMP)
os.environ["TMPDIR"] = tempfile.tempdir = SESSION_TMP
LEFT_IN_TMP = ("SB3-", "parallel-eplus-")  # SB3's default logger folders; our pipes and temporary episodes


# Tests that start a Ray of their own (ray.init, a Ray backend or evaluation, a Tune sweep). Under pytest-xdist
# (`pytest -n 2`) they are one unit of work, run one after another on one worker: two Rays starting at once on 2
# loaded cores timed out ("The current node timed out during startup"). Every other test goes with its module, so a
# module's fixtures run once, as they do without xdist.
RAY_TESTS = (
    "tests/faults/test_overlap_faults.py::test_ctrl_c_during_an_overlapped_update_saves_a_checkpoint_stops_the_collec",
    "tests/faults/test_overlap_faults.py::test_an_actor_lost_during_an_overlapped_update_ends_the_run_after_a_check",
    "tests/faults/test_ray_faults.py::",
    "tests/test_bench.py::test_bench_measures_everything_and_writes_json",  # its Ray backend row
    "tests/test_comfort_constraint.py::test_ray_actors_return_the_costs_their_workers_reported",
    "tests/test_evaluate.py::test_a_sweep_through_ray_tasks_gives_the_local_sweeps_table_and_figures",
    "tests/test_evaluate.py::test_ctrl_c_in_a_ray_evaluation_leaves_no_process_and_no_episode_folder",
    "tests/test_model_based.py::test_the_ray_backend_runs_the_planner_too",
    "tests/test_optimize.py::test_a_portfolio_on_ray",
    "tests/test_overlap.py::test_overlapped_batches_hold_every_workers_steps_once_in_order_with_their_costs",
    "tests/test_rllib.py::",
    "tests/test_rollout.py::test_ray_actors_collect_the_batch_local_workers_collect",
    "tests/test_sweep.py::",
    "tests/test_sweep_eval.py::",
    "tests/test_sweep_job.py::",
    "tests/test_train.py::test_ray_backend_trains_locally",
    "tests/test_vector_env.py::test_ray_backend_starts_its_own_ray_despite_a_stale_cluster",
)


# Of those, the tests that use a Ray without being about Ray's own start and stop: they share one per test process
# (see `_a_shared_ray_for_the_ray_users`). The others start and end their own: a Ctrl-C or a lost actor's clean-up
# that must leave no Ray, a Ray started despite a stale cluster, a subprocess, the bench's timings, RLlib's own init.
SHARED_RAY_TESTS = (
    "tests/faults/test_ray_faults.py::test_an_energyplus_worker_killed_inside_an_actor_restarts_there_and_the_run",
    "tests/faults/test_ray_faults.py::test_a_lost_actor_stops_the_run_naming_its_node_after_a_checkpoint_that_res",
    "tests/faults/test_ray_faults.py::test_a_failed_ray_episode_leaves_the_evaluation_standing",
    "tests/test_comfort_constraint.py::test_ray_actors_return_the_costs_their_workers_reported",
    "tests/test_evaluate.py::test_a_sweep_through_ray_tasks_gives_the_local_sweeps_table_and_figures",
    "tests/test_model_based.py::test_the_ray_backend_runs_the_planner_too",
    "tests/test_overlap.py::test_overlapped_batches_hold_every_workers_steps_once_in_order_with_their_costs[ray-",
    "tests/test_rollout.py::test_ray_actors_collect_the_batch_local_workers_collect",
    "tests/test_sweep.py::test_two_seeds_queue_two_workers_each_and_both_finish_as_run_folders",
    "tests/test_sweep.py::test_a_failing_trial_is_reported_and_the_others_finish",
    "tests/test_sweep.py::test_an_optuna_search_draws_its_trials_and_names_the_best",
    "tests/test_sweep_eval.py::test_a_search_chooses_by_evaluation_and_prints_the_winning_configuration",
    "tests/test_sweep_eval.py::test_asha_stops_a_trailing_trial_early_and_seeds_draw_one_curve_with_its_band",
    "tests/test_sweep_eval.py::test_pbt_continues_the_trailing_trial_from_the_leaders_weights_with_perturbed_se",
    "tests/test_train.py::test_ray_backend_trains_locally",
)
SHARED_RAY_CPUS = 2  # what the tests' queues assume (two seeds of two workers each wait for each other)
_shared_ray: list[bool] = []  # whether this test process's shared Ray is up


def _stop_shared_ray() -> None:
    if _shared_ray:
        import ray

        ray.shutdown()
        _shared_ray.clear()


@pytest.fixture(autouse=True)
def _a_shared_ray_for_the_ray_users(request):
    """A SHARED_RAY_TESTS test runs on its process's one Ray, started by the package's own `connect` before it (as a
    user's `ray.init` before `train` would be: our code then joins it and leaves it up), which saves a Ray start and
    stop, 15-25 s on 2 loaded cores, per test. After it every core must be free again: an actor or trial left behind
    fails the test (and the Ray is ended). Any other test finds no Ray up: it starts its own, or forks without Ray's
    threads in the process."""
    if not request.node.nodeid.startswith(SHARED_RAY_TESTS):
        _stop_shared_ray()
        yield
        return
    import ray

    from parallel_eplus.envs.ray_session import connect

    if not _shared_ray:
        connect(None, SHARED_RAY_CPUS)
        _shared_ray.append(True)
    yield
    deadline = time.monotonic() + 30
    while (free := ray.available_resources().get("CPU", 0.0)) < SHARED_RAY_CPUS:
        if time.monotonic() > deadline:
            _stop_shared_ray()
            pytest.fail(f"the test left Ray work holding {SHARED_RAY_CPUS - free:g} of {SHARED_RAY_CPUS} CPUs")
        time.sleep(0.2)


# Tests on a wall clock: a BACnet device stepping every 0.3-0.5 s that a supervisor must act within, or an answer
# due within a few seconds. Marked `realtime`; .ci/run runs them alone, after the rest: beside a second test process
# on 2 loaded cores, one of them missed a step and one took 5.6 s for 3.
REALTIME_TESTS = (
    "tests/faults/test_energyplus.py::test_killed_energyplus_raises_promptly_and_leaves_nothing",
    "tests/faults/test_energyplus.py::test_hung_energyplus_hits_the_timeout",
    "tests/test_bacnet.py::test_in_accelerated_real_time_the_supervisor_follows_the_device_s_clock",
    "tests/test_bacnet.py::test_a_device_with_only_its_points_is_supervised_on_the_supervisor_s_own_clock",
    "tests/test_bacnet.py::test_a_supervisor_that_cannot_reach_its_device_says_why_within_seconds",
    "tests/test_fork.py::test_a_forked_episode_killed_mid_episode_raises_promptly_and_the_env_recovers",
    "tests/test_fork.py::test_close_ends_the_templates_and_their_children_and_removes_their_directories",
    "tests/test_vector_env.py::test_pipelined_worker_that_crashes_or_hangs_restarts_alone",
)


# The longest units of work under pytest-xdist, longest first (seconds on a quiet 2-core VM, 2026-12-07): they start
# first, so the last units to run are short ones. In xdist's own order (by number of tests) the installed wheel's one
# test (150 s) started last and ran alone while the other process had finished.
LONG_SCOPES = (
    "ray",  # 990 s
    "tests/test_installed_wheel.py",  # 150 s
    "tests/test_train.py", "tests/test_building_init.py", "tests/test_mbpo.py", "tests/test_optimize.py",  # 85-95 s
    "tests/faults/test_trainer_faults.py", "tests/test_model_based.py", "tests/test_periodic_eval.py",  # 80-85 s
    "tests/faults/test_soak.py",  # 75 s, one test
)  # fmt: skip


def _scope(nodeid: str) -> str:
    """A test's unit of work under pytest-xdist: "ray" for RAY_TESTS, else its module."""
    return "ray" if nodeid.startswith(RAY_TESTS) else nodeid.split("::", 1)[0]


def pytest_collection_modifyitems(config, items):
    for item in items:
        if item.nodeid.startswith(REALTIME_TESTS):
            item.add_marker(pytest.mark.realtime)
    if os.environ.get("PYTEST_XDIST_WORKER"):  # each test process collects; the scheduler takes units in this order
        rank = {scope: i for i, scope in enumerate(LONG_SCOPES)}
        items.sort(key=lambda item: rank.get(_scope(item.nodeid), len(LONG_SCOPES)))  # stable: files' order after


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config, log):
    """pytest-xdist's scheduling by scope (`--dist loadscope`), the scope a test's module or, for RAY_TESTS, "ray";
    units in the collection's order (LONG_SCOPES first), not xdist's by number of tests."""
    from xdist.scheduler import LoadScopeScheduling

    class ModulesAndRayApart(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            return _scope(nodeid)

    config.option.loadscopereorder = False
    return ModulesAndRayApart(config, log)


def pytest_sessionfinish(session, exitstatus):
    """Nothing of ours may stay in the temp folder: fail the session, naming what was left, then tidy up."""
    _stop_shared_ray()
    left = sorted(n for n in os.listdir(SESSION_TMP) if n.startswith(LEFT_IN_TMP))
    if left:
        reporter = session.config.pluginmanager.get_plugin("terminalreporter")
        if reporter is not None:
            reporter.write_line(f"\nFAILED: the tests left in the temp folder: {', '.join(left)}", red=True)
        session.exitstatus = pytest.ExitCode.TESTS_FAILED
    shutil.rmtree(SESSION_TMP, ignore_errors=True)


def _started_by_us(pid: str) -> bool:
    try:
        return MARKER.encode() in Path(f"/proc/{pid}/environ").read_bytes().split(b"\0")
    except OSError:  # gone meanwhile, or not ours to read
        return False


def our_processes() -> list[str]:
    """EnergyPlus-side processes this test session started that are still alive (a leak)."""
    out = subprocess.run(["pgrep", "-af", "parallel_eplus.engine.eplus_side.callback"], capture_output=True, text=True)
    return [ln for ln in out.stdout.splitlines() if ln.strip() and _started_by_us(ln.split()[0])]


def _held_by_another_run(path: str) -> bool:
    """Whether a process outside this test session has a file in `path` open: the pipes of a training
    run sharing the machine, which are not ours to count."""
    prefix = path.rstrip("/") + "/"
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit() or int(proc.name) == os.getpid() or _started_by_us(proc.name):
            continue
        try:
            if any(os.readlink(fd).startswith(prefix) for fd in (proc / "fd").iterdir()):
                return True
        except OSError:  # gone meanwhile, or not ours to read
            continue
    return False


def _owned_by_another_run(path: str) -> bool:
    """Whether the directory names its owner (engine/pipes/leftovers.py) and that owner is not this session's."""
    try:
        pid = (Path(path) / "owner").read_text().split()[0]
    except (OSError, IndexError):
        return False
    return int(pid) != os.getpid() and not _started_by_us(pid)


def our_pipe_dirs(tmp: str | None = None) -> set[str]:
    """Pipe directories under `tmp` (a `parallel-eplus-*` folder with an `act` FIFO), less those of
    another run on the machine: named as another process's, or held open by one."""
    tmp = tmp or tempfile.gettempdir()
    if not os.path.isdir(tmp):  # the session's own, removed at its end (an interrupted session tears down late)
        return set()
    names = {
        d for d in os.listdir(tmp) if d.startswith("parallel-eplus-") and os.path.exists(os.path.join(tmp, d, "act"))
    }
    return {
        d for d in names
        if not _owned_by_another_run(os.path.join(tmp, d)) and not _held_by_another_run(os.path.join(tmp, d))
    }  # fmt: skip


@pytest.fixture
def no_leaks():
    """Fails the test if it leaves an EnergyPlus process or a pipe directory behind."""
    before = our_pipe_dirs()
    yield
    assert our_processes() == []
    assert our_pipe_dirs() - before == set()


@pytest.fixture
def broken_weather(tmp_path) -> Path:
    """An EPW cut after its header: EnergyPlus starts, then stops on its first weather line."""
    from parallel_eplus.buildings.weather.files import resolve_weather

    broken = tmp_path / "Broken.epw"
    broken.write_text("".join(resolve_weather("CA").read_text(encoding="latin-1").splitlines(True)[:8]))
    return broken
