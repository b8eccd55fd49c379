"""What acts in an evaluation episode: the built-in controls, the rule-based controller or a saved policy.

A `Controller` is one column of the paper's table: a label and how it acts. `policy_controller` reads a run's
saved settings (its building, observation features, residual), so a policy is evaluated as it was trained.
"""

from __future__ import annotations

import inspect
import json
import logging
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from parallel_eplus.buildings.building import Building, load_building
from parallel_eplus.buildings.resources import saved_building
from parallel_eplus.buildings.rules.datacenter import RBCConfig, RuleBasedController
from parallel_eplus.buildings.weather.files import weather_label
from parallel_eplus.engine.config import SimulationConfig
from parallel_eplus.errors import EnergyPlusError

log = logging.getLogger(__name__)

BASELINE_LABEL = "Baseline"
RBC_LABEL = "Rule-based"
# kind "oracle" (learning/oracle/): plans on EnergyPlus itself, forking the running episode (SimulationConfig's
# `branching`); its actor is given the episode's Simulation (`bind`) before the first step
ORACLE_KIND = "oracle"


@dataclass
class Controller:
    """One column of the paper's table: a label and how it acts."""

    label: str
    # "baseline", "policy", "rbc", "http" (a served controller: `url`) or "planner" (a model-based run's:
    # learning/model_based/control/mpc.py)
    kind: str
    path: Path | None = None
    time_features: bool = False  # the policy observes model.TIME_FEATURES
    schedule_features: bool = False  # and model.SCHEDULE_FEATURES
    rbc_target_c: float | None = None  # the rule-based controller's zone target; None: RBCConfig's
    rule: str | None = None  # "module:Class": the rule-based controller instead of the spec's `controller`
    residual_scale: float = 0.0  # > 0: the policy corrects the rule-based controller (SimulationConfig)
    residual_space: str = "action"  # what the correction applies to (SimulationConfig)
    building: str | None = None  # the spec a policy was trained on (its config.json); None: the data center
    run: str = ""  # a policy's training run (its folder's name): policies sharing a label are one recipe's runs
    # A policy in memory, (observation, info) -> action: evaluation during training (training/periodic_eval.py)
    act: Callable[[np.ndarray, dict], np.ndarray] | None = None
    url: str | None = None  # "http": where `parallel-eplus serve` answers
    token: str | None = field(default=None, repr=False)  # "http": the bearer token it asks for (never shown)
    served: dict | None = None  # "http": the contract's `policy` block (what was exported: its file and sha256)
    forecast_hours: int = 0  # the policy observes the outdoor dry bulb's next hours (train --forecast)
    forecast_error: str | None = None
    # kind "planner": makes the episode's actor; given by the layer that knows the planner (picklable, for Ray)
    factory: Callable[[], Callable[[np.ndarray, dict], np.ndarray]] | None = None

    @property
    def model(self) -> str:
        return "baseline" if self.kind == "baseline" else "temp_fan"

    def relinquishes(self, building: str | Building | None) -> bool:
        """Whether its NaN action elements release their actuators to the building's own control (a rule-based
        controller that says so: buildings/rules/air_reset.py); the episode then runs with `relinquish`."""
        return self._rule_says(building, "relinquishes")

    def residual(self, building: str | Building | None) -> tuple[float, str]:
        """(residual_scale, residual_space) for its episodes: a policy's as trained, or, for a rule-based controller
        whose actions correct the building's own schedules (`corrects_own`: buildings/rules/own_margin.py), "builtin" at
        scale 1, so EnergyPlus's side adds them to each schedule at the step it applies to."""
        if self._rule_says(building, "corrects_own"):
            return 1.0, "builtin"
        return self.residual_scale, self.residual_space

    def _rule_says(self, building: str | Building | None, flag: str) -> bool:
        if self.kind != "rbc" or not (building or self.rule):
            return False
        return bool(getattr(load_building(building).controller_class(self.rule), flag, False))

    def make(self, building: str | Building | None = None) -> Callable[[np.ndarray, dict], np.ndarray]:
        """A fresh actor for one episode: (observation, info) -> action. `building`: the swept spec (or its
        `Building`, resolved: what a rule class taking `building` is given), whose `controller` ("module:Class") is
        the rule-based one; None: the data center's."""
        if self.kind == "baseline":
            empty = np.zeros(0, dtype=np.float32)
            return lambda obs, info: empty
        if self.kind == "rbc":
            target = {} if self.rbc_target_c is None else {"target_c": self.rbc_target_c}
            named = building or self.rule  # a rule named on the command line acts on the default building too
            b = load_building(building) if named else None
            cls = b.controller_class(self.rule) if b else RuleBasedController
            if cls is RuleBasedController:
                return RuleBasedController(RBCConfig(**target), building)
            if "building" in inspect.signature(cls).parameters:  # a class that reads the spec it acts on
                target["building"] = building
            if self.rule in (None, b.spec.controller):  # the spec's own rule: with the spec's settings for it
                target |= dict(b.spec.controller_settings)
            return cls(**target)  # a user's class: called (observation, info) -> normalized action
        if self.act is not None:
            return self.act
        if self.kind == "http":
            from parallel_eplus.evaluation.http_controller import HttpController

            return HttpController(self.url, token=self.token)
        if self.factory is not None:
            return self.factory()
        from parallel_eplus.runs.policy_files import load_policy

        act = load_policy(self.path)
        return lambda obs, info: act(obs[None, :])[0]


def policy_controllers(spec: str) -> list[Controller]:
    """`policy_controller` for a policy, a run folder, or a folder of runs (a sweep's, or any: every run under it
    that has a model.zip, labelled by the folder's name unless LABEL is given: one recipe's seeds)."""
    path_text, _, label = spec.partition("=")
    path = Path(path_text)
    if path.is_dir() and not (path / "model.zip").is_file():
        runs = sorted(p.parent for p in path.glob("*/model.zip"))
        if not runs:
            raise FileNotFoundError(f"{path}: no model.zip in it or in a run folder below it")
        return [policy_controller(f"{run}={label or path.name}") for run in runs]
    return [policy_controller(spec)]


def policy_controller(spec: str) -> Controller:
    """'runs/A/model.zip' or 'runs/A/model.zip=LABEL'; the label defaults to 'TRPO (<training weathers>)'."""
    path_text, _, label = spec.partition("=")
    path = Path(path_text)
    if path.is_dir():
        path = path / "model.zip"
    from parallel_eplus.engine.config import policy_action_names
    from parallel_eplus.runs.policy_files import (
        check_actions,
        policy_features,
        policy_forecast,
        require_policy_files,
        run_dir_of,
    )

    require_policy_files(path)
    config = run_dir_of(path) / "config.json"
    saved = json.loads(config.read_text()) if config.is_file() else {}
    residual = float(saved.get("residual_scale", 0.0))
    if not label and saved:
        corrects = "+own" if saved.get("residual_space") == "builtin" else "+RBC"  # what a residual policy corrects
        algorithm = saved.get("algorithm", "trpo").upper() + (corrects if residual else "")
        label = f"{algorithm} ({'-'.join(saved['weathers'])})"
    space = saved.get("residual_space", "action")
    building = saved_building(saved)
    time_features, schedule_features = policy_features(path, building)
    sim = SimulationConfig(
        model=saved.get("model", "temp_fan"), building=building, residual_scale=residual,
        residual_space=space,
    )  # fmt: skip
    what = f"building {Path(sim.building).stem}" if sim.building else f"model {sim.model}"
    what += f" with residual space {space}" if residual else ""
    check_actions(path, len(policy_action_names(sim)), what)
    if sim.model != "temp_fan":
        raise ValueError(f"{path}: trained on model {sim.model!r}; the evaluation sweep runs temp_fan")
    return Controller(
        label or path.parent.name, "policy", path, time_features, schedule_features,
        rbc_target_c=saved.get("rbc_target_c"), residual_scale=residual,
        residual_space=saved.get("residual_space", "action"), building=building,
        run=saved.get("run_name") or run_dir_of(path).name, forecast_hours=policy_forecast(path)[0],
        forecast_error=policy_forecast(path)[1],
    )  # fmt: skip


def http_controller(url: str, token: str | None = None) -> Controller:
    """A controller served at `url`, labelled by its contract's algorithm and run; it acts in the building it was
    exported for (the features it observes are computed by the server from each step's time). `token`: the bearer
    token the server asks for."""
    from parallel_eplus.evaluation.http_controller import HttpController

    client = HttpController(url, token=token)
    try:
        policy = client.contract["policy"]
        what = "MPC planner" if client.planner else policy["algorithm"].upper()
        return Controller(f"{what} via HTTP ({policy['run']})", "http", building=client.building(),
                          run=str(policy["run"]), url=url, token=token, served=dict(policy))  # fmt: skip
    finally:
        client.close()


def check_same_controllers(local: list[Controller], served: list[Controller]) -> None:
    """`evaluate --policy P --controller-url U` compares a controller in process with one served: refused when P
    is of the run U was exported from but another of its files (a model-based run's distilled network beside its
    served planner: `export` serves `best/planner`), with the --policy that is; a WARNING when no --policy is of
    U's run at all (two different controllers side by side: fine if meant)."""
    import hashlib

    learned = [c for c in local if c.kind in ("policy", "planner") and c.path is not None]
    for s in served:
        ours = [c for c in learned if c.run == s.run]
        same = [c for c in ours if hashlib.sha256(Path(c.path).read_bytes()).hexdigest() == s.served.get("sha256")]
        if ours and not same:
            c = ours[0]
            planner = s.served.get("algorithm") == "mpc"
            run_dir = next((d for d in Path(c.path).parents if d.name == s.run), Path(c.path).parent)
            best = run_dir / "best" / "planner"
            right = (best if best.is_dir() else run_dir / "planner") if planner else run_dir / s.served.get("model", "")
            raise ValueError(
                f"--policy {c.path} ({c.label}) is not the controller {s.url} serves, though both come from run "
                f"{s.run}: the server serves its {s.served.get('model')} (sha256 {s.served.get('sha256', '')[:12]}…)"
                f"{', the planner `export` wrote' if planner else ''}; give --policy {right} to compare the same "
                "controller in process and served"
            )
        if learned and not ours:
            log.warning("--controller-url %s serves run %s, which no --policy names (%s): the table puts different "
                        "controllers side by side", s.url, s.run, ", ".join(c.run for c in learned))  # fmt: skip


def unique_labels(controllers: list[Controller]) -> list[Controller]:
    """Policies sharing a label from different runs are one recipe's runs (seeds); any other repeat is renamed."""
    seen: dict[str, list[Controller]] = {}
    for c in controllers:
        earlier = seen.get(c.label, [])
        learned = c.kind in ("policy", "planner")
        seeds = earlier and learned and all(e.kind == c.kind and e.run != c.run for e in earlier)
        if earlier and not seeds:
            c.label = f"{c.label} [{c.path.parent.name if c.path else len(earlier) + 1}]"
        seen.setdefault(c.label, []).append(c)
    return controllers


def slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9]+", "-", text).strip("-").lower()


def failure_row(controller: Controller, cfg: SimulationConfig, error: EnergyPlusError) -> dict:
    """What a failed episode leaves in the sweep's report: who, where, EnergyPlus's own words, the folder."""
    log.error("%s on %s failed: %s", controller.label, weather_label(cfg.weather), error)
    return {
        "controller": controller.label,
        "weather": weather_label(cfg.weather),
        "error": error.headline,
        "episode_dir": str(getattr(error, "episode_dir", None) or cfg.output_dir),
    }
