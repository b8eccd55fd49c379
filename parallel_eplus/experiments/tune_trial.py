"""One trial of a sweep: an ordinary training run inside a Ray Tune trial, reporting each batch to Tune.

The trial's process is a Ray actor on one node; the run inside it is `train(cfg)` with the local backend,
its EnergyPlus workers children of that process, its folder `runs/<sweep>/<trial>/` like any run's. The
training runs in a thread of ours, not Tune's function-trainable thread, so that stopping the trial
(Ctrl-C on the sweep, `ray job stop`, the end of the sweep) waits for it: `cleanup` asks the run to stop,
the run saves a checkpoint and stops its EnergyPlus workers, and only then does the trial's process end.
"""

from __future__ import annotations

import json
import logging
import math
import os
import queue
import shutil
import signal
import threading
import time
import zipfile
from pathlib import Path

import pandas as pd
from ray import tune
from stable_baselines3.common.callbacks import BaseCallback

from parallel_eplus.experiments.sweep_rank import trial_evaluation
from parallel_eplus.experiments.sweep_spec import trial_config
from parallel_eplus.runs.policy_files import MODEL_FILE, saves_newest_first
from parallel_eplus.runs.run_files import latest_evaluation, saved_steps
from parallel_eplus.runs.run_status import TRIAL_VARIABLE
from parallel_eplus.training.callbacks import episodes_per_weather

log = logging.getLogger(__name__)

STOP_WAIT_S = 300.0  # how long a stopping trial waits for its checkpoint and workers to close
PBT_FILE = "pbt.json"  # each exploit: which save the trial continued from, at what step, with which settings


class TrialStopped(KeyboardInterrupt):
    """The sweep stopped this trial: train() saves a checkpoint and closes the workers, as on Ctrl-C."""


class TuneReport(BaseCallback):
    """Each batch's end: steps done and the mean share in band, power and reward of the episodes that ended
    in it (the latest known when none did) with the run's best evaluation so far (sweep_rank.trial_evaluation),
    handed to `put`; raises TrialStopped once `stop` is set.

    With evaluation during training (`eval_every`), a batch whose end makes an evaluation due is reported after
    it instead (at the next batch's start: PeriodicEval runs before this callback), so a scheduler judges each
    rung by the evaluation taken there."""

    def __init__(self, put, stop: threading.Event, run_dir: Path | None = None, eval_every: int = 0,
                 min_interval_s: float = 2.0):  # fmt: skip
        super().__init__()
        self.put, self.stop, self.min_interval_s, self.run_dir = put, stop, min_interval_s, run_dir
        self.eval_every = eval_every
        self.latest = {"in_band_pct": math.nan, "power_kw": math.nan, "reward": math.nan}
        self.episodes = 0
        self._batch: list[dict] = []
        self._last = 0.0
        evaluated = latest_evaluation(run_dir) if run_dir is not None and eval_every else None
        self._evaluated = int(evaluated["timesteps"]) if evaluated else -1  # the newest evaluation's step

    def _on_step(self) -> bool:
        if self.stop.is_set():
            raise TrialStopped("the sweep stopped this trial")
        for info in self.locals["infos"]:
            final = info.get("final_info")
            if final and "episode_summary" in final:
                self._batch.append(final["episode_summary"])
        return True

    def _eval_due(self) -> bool:
        every = self.eval_every
        return bool(every) and self.num_timesteps // every > max(self._evaluated, 0) // every

    def _on_rollout_end(self) -> None:  # on-policy: once a batch; SAC: every step, so at most every 2 s
        if self._eval_due():
            return  # reported at the next batch's start, with the evaluation
        if not self._batch and time.monotonic() - self._last < self.min_interval_s:
            return
        self._report()

    def _on_rollout_start(self) -> None:
        if self._eval_due():  # PeriodicEval has just evaluated
            self._evaluated = self.num_timesteps
            self._report()

    def _report(self) -> None:
        if self._batch:
            for key, source in (("in_band_pct", "in_band_pct"), ("power_kw", "power_kw"), ("reward", "reward_mean")):
                values = [s[source] for s in self._batch if source in s]
                if values:
                    self.latest[key] = float(sum(values) / len(values))
            self.episodes += len(self._batch)
            self._batch = []
        self._last = time.monotonic()
        self.put(("result", self.result()))

    def result(self) -> dict:
        evaluation = trial_evaluation(self.run_dir) if self.run_dir is not None else {}
        return {"timesteps": int(self.num_timesteps), "episodes": self.episodes, **self.latest, **evaluation}


def _finished(cfg) -> dict | None:
    """A finished run's last result (its final model reached the planned steps), or None."""
    saves = saves_newest_first(cfg.run_dir)
    if not saves or saves[0].name != MODEL_FILE:
        return None
    with zipfile.ZipFile(saves[0]) as z:
        steps = int(json.loads(z.read("data"))["num_timesteps"])
    if steps < cfg.timesteps:
        return None
    episodes = pd.read_csv(cfg.run_dir / "episodes.csv")
    last = episodes[episodes["timesteps"] > steps - cfg.batch_size]  # the last batch's episodes
    means = {"in_band_pct": "in_band_pct", "power_kw": "power_kw", "reward": "reward_mean"}
    return {"timesteps": steps, "episodes": len(episodes), **{k: float(last[c].mean()) for k, c in means.items()},
            **trial_evaluation(cfg.run_dir)}  # fmt: skip


def _has_save(cfg) -> bool:
    """Whether the trial's folder holds a save to continue from: SB3's, or a model-based run's (its own files)."""
    if cfg.algorithm == "mpc":
        from parallel_eplus.learning.model_based.control.checkpoint import newest_checkpoint

        try:
            newest_checkpoint(cfg.run_dir)
        except FileNotFoundError:
            return False
        return True
    return bool(saves_newest_first(cfg.run_dir))


def _wait_for_predecessor(run_dir: Path) -> None:
    """A trial Tune restarts (PBT's exploit, a restored sweep) may start before its previous process has saved
    its stop's checkpoint: wait for that process to end, so the newest save is the one meant."""
    from parallel_eplus.runs.registry import process_alive
    from parallel_eplus.runs.run_files import read_status

    deadline = time.monotonic() + STOP_WAIT_S
    while (status := read_status(run_dir)) and status["state"] == "running" and status.get("pid") != os.getpid():
        if not process_alive(status) or time.monotonic() > deadline:
            return
        time.sleep(0.5)


def exploit(donor: Path, cfg, at_steps: int) -> None:
    """PBT: this trial continues from `donor`'s newest save with its own (perturbed) settings: the save and its
    statistics are copied into this run's checkpoints/ and its config.json rewritten, so `train --resume` takes
    both (training/resume_settings.py: the settings a resumed run takes from its config)."""
    from parallel_eplus import io
    from parallel_eplus.runs.policy_files import normalization_file, stats_target

    saves = [p for p in saves_newest_first(donor) if saved_steps(p) <= at_steps] or saves_newest_first(donor)
    if not saves:
        log.warning("trial %s: PBT's donor %s has no save yet; continuing from its own", cfg.run_name, donor)
        return
    steps = saved_steps(saves[0])
    target = cfg.run_dir / "checkpoints" / f"model_{steps}_steps.zip"
    target.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(normalization_file(saves[0]), stats_target(target))
    shutil.copyfile(saves[0], target)
    for newer in (p for p in saves_newest_first(cfg.run_dir) if p != target):  # the donor's save is the newest
        if newer.name == MODEL_FILE or int(newer.stem.split("_")[1]) >= steps:
            newer.rename(newer.with_name(f"superseded-{newer.name}"))
    io.write_text(cfg.resolved().run_dir / "config.json", cfg.to_json())
    history = cfg.run_dir / PBT_FILE
    earlier = json.loads(history.read_text()) if history.is_file() else []
    settings = {k: v for k, v in json.loads(cfg.to_json()).items() if k in ("trpo", "ppo", "sac")}
    io.write_text(history, json.dumps([*earlier, {"from": str(saves[0]), "steps": steps, "settings": settings}],
                                      indent=2))  # fmt: skip
    log.info("trial %s: PBT: continues from %s (step %d) with its perturbed settings", cfg.run_name, saves[0], steps)


class TrialRun(tune.Trainable):
    """A sweep's trial: `setup` starts the run in a thread, `step` hands Tune its next batch's result,
    `cleanup` stops it with a checkpoint. A trial whose run folder holds a checkpoint continues from it."""

    def setup(self, config, base=None, runs_dir="runs", tensorboard_dir="tensorboard_logs"):
        os.environ[TRIAL_VARIABLE] = self.trial_name  # the run's status.json names its trial (`parallel-eplus runs`)
        logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")  # as train's are
        if threading.current_thread() is threading.main_thread():  # a signal to this trial stops it alone
            for sig in (signal.SIGINT, signal.SIGTERM):
                signal.signal(sig, self._on_signal)
            signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})  # Ray's workers block it
        self._results: queue.Queue = queue.Queue()
        self._stop = threading.Event()
        self._run_dir = Path(runs_dir) / self.trial_name
        self._donor: Path | None = None  # PBT: the better trial whose weights this one continues from
        self._donor_steps = 0  # its step when PBT chose it: its newest save up to there is copied
        self._last_steps = 0  # the latest step reported to Tune
        self._thread = threading.Thread(
            target=self._train, args=({**(base or {}), **config}, runs_dir, tensorboard_dir),
            name=f"train {self.trial_name}", daemon=True,
        )  # fmt: skip
        # started by the first `step`: Tune restores a checkpoint (`load_checkpoint`, PBT's exploit) in between

    def _on_signal(self, signum, frame) -> None:
        """SIGINT or SIGTERM to the trial's process (`kill`, a run registry's stop) stops this trial as Ctrl-C
        stops `train`: a checkpoint, its workers gone; the sweep goes on with the others."""
        if self._thread.ident is not None and not self._thread.is_alive():  # Tune ends a finished trial's process so
            log.info("trial %s: finished; its process ends (signal %d)", self.trial_name, signum)
            return
        log.warning("trial %s: signal %d; stopping with a checkpoint", self.trial_name, signum)
        self._stop.set()

    def _train(self, settings: dict, runs_dir: str, tensorboard_dir: str) -> None:
        from parallel_eplus.training.train import train

        report = TuneReport(self._results.put, self._stop)
        try:
            cfg = trial_config(settings, runs_dir, tensorboard_dir, self.trial_name)
            report = TuneReport(self._results.put, self._stop, cfg.run_dir, cfg.evaluation.every)
            done = _finished(cfg)
            if done is not None:  # a sweep run again: this trial had finished
                self._results.put(("done", done))
                return
            _wait_for_predecessor(cfg.run_dir)
            if self._donor is not None:
                exploit(self._donor, cfg, self._donor_steps)
            resume = cfg.run_dir if _has_save(cfg) else None
            report.episodes = sum(episodes_per_weather(cfg.run_dir / "episodes.csv").values()) if resume else 0
            # a folder without a checkpoint (a trial killed early) is moved aside, not trained into
            train(cfg, resume=resume, progress=False, overwrite=resume is None, callbacks=[report])
            self._results.put(("done", report.result()))
        except TrialStopped:
            self._results.put(("stopped", report.result()))
        except BaseException as e:  # noqa: BLE001 - Tune reports it as this trial's error; the others go on
            text = str(e).strip()
            headline = getattr(e, "headline", None) or (text.splitlines()[0] if text else repr(e))
            detail = f"\n{text}" if text and text != headline else ""
            self._results.put(("error", RuntimeError(f"{type(e).__name__}: {headline}{detail}")))

    def step(self) -> dict:
        if self._thread.ident is None:
            self._thread.start()
        kind, payload = self._results.get()
        if kind == "error":
            raise payload
        self._last_steps = int(payload.get("timesteps", self._last_steps)) if isinstance(payload, dict) else 0
        if kind == "done":
            log.info("trial %s: finished at step %d", self.trial_name, payload.get("timesteps", 0))
        # "finished": ended by itself (Tune also marks done the last result of a trial its scheduler stops)
        return {**payload, "done": kind != "result", "stopped": kind == "stopped", "finished": kind == "done"}

    def save_checkpoint(self, checkpoint_dir: str) -> dict:
        """Tune's own checkpoint only points at the run: its checkpoints are the run folder's."""
        return {"run_dir": str(self._run_dir), "timesteps": self._last_steps}

    def load_checkpoint(self, checkpoint: dict) -> None:
        """Its own checkpoint: nothing to load (the run continues from its folder's last save). Another trial's
        (PBT's exploit): that trial's newest save is copied in and this run continues from it (`exploit`)."""
        donor = Path(checkpoint.get("run_dir", "")) if isinstance(checkpoint, dict) else None
        if donor is not None and donor.resolve() != self._run_dir.resolve():
            self._donor, self._donor_steps = donor, int(checkpoint.get("timesteps", 1 << 62))

    def cleanup(self) -> None:
        self._stop.set()
        self._thread.join(STOP_WAIT_S)
        if self._thread.is_alive():
            log.warning("trial %s did not stop within %.0f s", self.trial_name, STOP_WAIT_S)
