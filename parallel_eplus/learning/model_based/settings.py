"""`train --algorithm mpc`'s settings (the model, the data it learns from, the planner, the student) and `--algorithm
mbpo`'s: plain data classes, each field with its one line for `--mpc help` / `--mbpo help`."""

from __future__ import annotations

import functools
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar, Literal

from parallel_eplus.learning.model_based.runtime.renamed import RENAMED, renamed, renamed_settings
from parallel_eplus.learning.settings import FromText, setting


@dataclass
class MPCSettings(FromText):
    """The model-based learner's settings (`train --algorithm mpc`; `evaluate --planner` overrides a saved planner's).

    Saved in the run's config.json and in every planner checkpoint. Each field's one line is `--mpc help`'s; the
    comments beside them keep the measurements behind the defaults.
    """

    flag: ClassVar[str] = "--mpc"
    SECTIONS: ClassVar[dict[str, str]] = {
        "members": "The ensemble (model/dynamics.py): members, hidden layers, fitting",
        "record_days": "The data: the building's own controls recorded, replayed with an exploring offset, then the "
        "planner's own steps",
        "horizon": "The planner: CEM over increments of the last action (runtime/planner.py)",
        "comfort_weight": "What a plan costs besides energy",
        "consensus": "Against the baseline: the building's own controls' plan (with comfort_reference=baseline)",
        "noise": "Exploration in training",
        "distill": "The policy network (the student `export` takes)",
    }

    # The ensemble (dynamics.py): members, hidden layers, fitting.
    members: int = setting(5, "networks in the ensemble (their spread is the model's uncertainty)")
    hidden: int = setting(64, "units in each hidden layer of a member")
    epochs: int = setting(30, "passes over the data at the first fit")
    refit_epochs: int = setting(5, "passes over the data at each refit of the Dyna loop (warm-started)")
    learning_rate: float = setting(2e-3, "the members' learning rate (Adam)")
    batch_size: int = setting(256, "transitions per gradient step when fitting a member")
    # The data (sources.py, training/mpc.py): the building's own controls are recorded first (`record_days` per
    # training weather, None: the run's episode length), then `explore_steps` env steps replay them with an offset
    # walking toward random targets, then the planner acts; the model is refitted every `refit_every` env steps.
    record_days: int | None = setting(
        None, "days of the building's own controls recorded per training weather first (none: the episode length)"
    )
    explore_steps: int = setting(2_000, "env steps after the record replaying it with an offset walking to random "
                                 "targets, before the planner acts")  # fmt: skip
    explore_increment: float = setting(
        0.15, "the exploring walk's largest step per control step (normalized action units)"
    )
    explore_offset: float = setting(
        2.0, "the walk's targets' largest distance from the recorded action (normalized units; 2: the whole box)"
    )
    explore_hold: int = setting(32, "control steps a walk's target is held: 4 to this many")
    refit_every: int = setting(2_000, "env steps between refits of the model on all its data (the Dyna loop)")
    # The planner (planner.py): CEM over increments of the last action.
    horizon: int = setting(8, "control steps the planner looks ahead (8 x 15 min = 2 h)")
    candidates: int = setting(256, "action sequences sampled per CEM iteration")
    iterations: int = setting(3, "CEM iterations per decision")
    elites: int = setting(32, "best candidates CEM refits its sampling distribution to")
    shrink: float = setting(1.0, "each CEM iteration after the first samples this share of the previous one's "
                            "candidates and elites, within (0, 1]")  # fmt: skip
    # A thermostat's setback-to-occupied jump spans 1.5-1.7 of a prototype's range: below that the planner reaches
    # it a step late (`MPC.own_jump`).
    max_increment: float = setting(
        0.15, "largest change of each action per control step (normalized units; 2: the whole range)"
    )
    init_std: float = setting(0.1, "CEM's first standard deviation of each increment (normalized units)")
    # A model knows nothing beyond its data, and a planner fitted on the building's own controls alone drove the
    # data center out of EnergyPlus's range within 9 hours. The range grows with the planner's own steps at each
    # refit (Dyna), by up to this much each time.
    support_margin: float = setting(0.1, "the planner's actions stay within each action's range in the data "
                                    "widened by this much (normalized units)")  # fmt: skip
    comfort_weight: float | None = setting(
        None, "fixed weight of the comfort term (none: the run's Lagrange multiplier, --comfort-target)"
    )
    # At 2 it outweighed the data center's savings tenfold and held the planner at the built-in controls' corner
    # (-2 % in a 14-day pilot); at 0.2 the planner goes where its data are thin, learns there (Dyna), and saves 25 %.
    disagreement_weight: float = setting(0.2, "cost per K of the members' spread in a zone temperature, per step "
                                         "(the energy term is ~1 a step)")  # fmt: skip
    # "worst" keeps the band if every member's prediction keeps it: a chance constraint from the ensemble's spread.
    comfort_risk: Literal["mean", "worst"] = setting(
        "mean", "the comfort term over the members: their average violation (mean) or the largest (worst)"
    )
    terminal_weight: float = setting(0.0, "the horizon's last step's comfort term counts 1 + this many times")
    # For a building scored against its own thermostats (`band = "thermostat"`): "all" is BOPTEST's total
    # discomfort; "occupied" its share in own bounds and occupied K.h (calendar.py). At every step, the warehouse's
    # planner heated at night against setbacks its own controls droop 0.3 K below, which no occupied score counts.
    comfort_hours: Literal["all", "occupied"] = setting(
        "all", "when discomfort costs: at every step, setbacks too (all), or in occupied hours only (occupied)"
    )
    # "baseline": what exceeds the discomfort the building's own thermostats would have from the same state, played
    # through the same model (calendar.own_reference). A zone its own controls cannot hold either (the warehouse's
    # bulk storage, which has no cooling) then costs nothing to leave as it is; against the band, the planner
    # cooled its neighbours for it.
    comfort_reference: Literal["band", "baseline"] = setting(
        "band",
        "discomfort a plan pays for: all of it beyond the band (band), or only what exceeds the baseline's, the "
        "building's own controls' plan through the same model (baseline)",
    )
    # "baseline" (own_level.py): the warehouse's own controls keep 77.6 % in summer: against 99.8 % its multiplier
    # sat at its cap.
    comfort_level: Literal["target", "baseline"] = setting(
        "target",
        "the share in band the multiplier holds: --comfort-target's (target), or where lower the one the "
        "building's own controls (evaluate --baseline) kept on the same dates and weathers in the run's record "
        "(baseline)",
    )
    # The search picks the candidate the model likes best, and on the restaurants that was a plan its errors
    # favoured: HVAC x1.018 where the baseline was a candidate all along.
    consensus: bool = setting(
        False, "leave the baseline only where every member predicts the chosen plan costs less than it"
    )
    # The search's best of hundreds of candidates is the one the model's errors favour most (the optimizer's
    # curse): on the full-service restaurant the planner left its own thermostats' plan on 62-71 % of steps, by
    # +/-1 K, for a predicted saving the simulator did not pay out (gas +0.7 %, HVAC electricity +1 %, CO peak
    # heating).
    min_saving: float = setting(0.0, "leave the baseline only where the chosen plan's predicted cost is lower by at "
                                "least this share of the baseline's, within [0, 1) (0: any saving)")  # fmt: skip
    # In the data the model learns from, a zone's ventilation and heating start when its setpoint leaves the
    # setback: held at the setback when the schedule starts, the full-service restaurant's dining room fell 5 K in
    # a step, where the model predicted 0.1 K (docs/model-based.md). Off the baseline by a few tenths, the model
    # has seen the building; by 6 K, it has not.
    baseline_radius: float | None = setting(None, "each thermostat action kept within this much of the baseline's "
                                            "at every step (normalized units, 0-2; none: anywhere)")  # fmt: skip
    # The band applies by date as the calendar recorded it, else by the weekly majority. In a restaurant's data a
    # zone's ventilation and heating start when its setpoint leaves the setback, always together: told only the
    # setpoint, the model put the cold air's arrival down to the setpoint and predicted 0.1 K for a 5 K fall
    # (docs/model-based.md).
    occupancy_input: bool = setting(
        False, "the model also sees whether the building is occupied at each step's end (kept by a saved planner)"
    )
    # The realised test for leaving the baseline (guard.py). The model's error off the baseline is not in its
    # predicted saving (min_saving=0.1 was not safe, docs/model-based.md); the building's reply is.
    guard_k: float | None = setting(
        None,
        "a worker that left the baseline within guard_steps and whose zones end a step this many K (summed, "
        "where the band applies) beyond the baseline's predicted discomfort plays the baseline for guard_steps "
        "(none: no guard)",
    )
    guard_steps: int = setting(12, "with guard_k: the steps looked back, and the steps the baseline is then played")
    # A zone sits at its thermostat's setpoint, and its own setpoint is the bound: the quick-service restaurant's
    # planner raised the dining room's cooling setpoint 0.8 K above its own with the zone at 24.0 C, a move its data
    # never showed, and the zone rose 0.3 K past the bound (docs/model-based.md). Outside the band's hours the
    # planner moves as before.
    band_thermostats: Literal["free", "at_least_baseline", "baseline"] = setting(
        "free",
        "where the band applies, a thermostat action does anything the rest allows (free), conditions at least as "
        "much as the baseline (at_least_baseline: cooling no higher, heating no lower) or follows it (baseline)",
    )
    # As far as the horizon sees: the retail store's planner set back 0.6 K deeper than its own at night, the zones
    # met the morning's schedule 0.5 K colder, and its first occupied hour held most of its excess K.h
    # (docs/model-based.md).
    band_lead: int = setting(
        0, "band_thermostats also holds this many steps before the band starts (0: from its first step)"
    )
    # The margin `OwnMargin` gives a rule. Five prototypes' planners ended 0.08-0.2 occupied K.h above their own
    # controls over 20 fortnights with each thermostat on the baseline (docs/model-based.md); EnergyPlus holds a
    # zone within 0.01 K of its setpoint.
    baseline_margin: float = setting(0.0, "the baseline's thermostats this many K inside the building's own "
                                     "setpoints (heating higher, cooling lower), within [0, 1]")  # fmt: skip
    # "rule": the spec's `controller` (`--rbc`) run beside the planner on each worker (Guideline 36's supply-air
    # reset, rules/air_reset.py); the actions the rule releases keep the building's plan. The planner then improves
    # on the rule, as the data center's best policy corrects its rule, where against the constant 12.8 C of the DOE
    # VAV loops it was held within `baseline_radius` of it, far from where the reset saves (docs/model-based.md).
    baseline_source: Literal["building", "rule"] = setting(
        "building",
        "the baseline of the actions no thermostat schedule sets: what the building's own controls set "
        "(building: evaluate --baseline) or the spec's rule, run beside the planner (rule: evaluate --rbc)",
    )
    noise: float = setting(0.0, "exploration added to the planner's action in training (normalized units)")
    # Distillation (distill.py): the policy network fitted to the planner's own actions.
    distill: bool = setting(True, "fit a policy network to the planner (false: the run ends with the planner alone)")
    # DAgger (Ross et al. 2011). A policy cloned on the planner's own states alone drifted to 30 C in closed loop
    # (2 % in band on CA). A worker more than 2 K outside the band is steered by the planner meanwhile.
    dagger_share: float = setting(
        0.25,
        "the budget's last share: the network acts, the planner labels the states it visits, and the network "
        "is refitted on every label at each refit (DAgger)",
    )
    # "gradient": through_model.py. A six-sensor copy of the planner lost the band on the paper's data center
    # (78 %); the gradient student with the clock's features held 99.5 % in the pilots (docs/model-based.md, "A
    # network learned through the model").
    student: Literal["dagger", "gradient"] = setting(
        "dagger",
        "what the network learns from: the planner's actions (dagger), or the planner's own cost through "
        "the model, after a first clone, at each refit of DAgger's phase and at the end (gradient)",
    )
    student_updates: int = setting(
        1500, "student=gradient: gradient steps through the model at each refit and at the end"
    )
    student_batch: int = setting(256, "student=gradient: start states per gradient step")
    student_learning_rate: float = setting(3e-4, "student=gradient: the network's learning rate")
    student_comfort_weight: float = setting(
        1.0, "student=gradient: the comfort term's weight in its cost (the energy term is ~1 a step)"
    )
    # A network acts on a coarser view than its planner (no forecast, one action per state): on the paper's data
    # center, trained through the model at the planner's 0.5 K, seed 0's CO year held 99.56 % in band; at 0.6 K
    # every seed and weather held >= 99.64 % (docs/model-based.md, "A 0.6 K margin").
    student_margin: float | None = setting(
        None, "student=gradient: K inside the band's edges the network keeps to, > 0 (none: --comfort-margin)"
    )

    def __post_init__(self):
        for name in (new for new, values in RENAMED.values() if values):  # an old value: warned, renamed
            setattr(self, name, renamed(name, getattr(self, name), "MPCSettings")[1])
        super().__post_init__()  # each Literal setting one of its words
        if not 0 < self.shrink <= 1:
            raise ValueError(f"shrink {self.shrink}: within (0, 1]")
        if self.baseline_radius is not None and not 0 <= self.baseline_radius <= 2:
            raise ValueError(f"baseline_radius {self.baseline_radius}: normalized units, within [0, 2]")
        if self.guard_k is not None and self.guard_k < 0:
            raise ValueError(f"guard_k {self.guard_k}: K beyond the baseline's predicted discomfort, >= 0")
        if not 0 <= self.baseline_margin <= 1:
            raise ValueError(
                f"baseline_margin {self.baseline_margin}: K inside the building's own setpoints, within [0, 1]"
            )
        if self.band_lead < 0:
            raise ValueError(f"band_lead {self.band_lead}: steps before the band, >= 0")
        if self.guard_steps < 1:
            raise ValueError(f"guard_steps {self.guard_steps}: steps, >= 1")
        if self.student_margin is not None and self.student_margin <= 0:
            raise ValueError(f"student_margin {self.student_margin}: K inside the band, > 0")
        if not 0 <= self.min_saving < 1:
            raise ValueError(f"min_saving {self.min_saving}: a share of the baseline's cost, within [0, 1)")

    @classmethod
    def renamed(cls, key: str, text: str, flag: str) -> tuple[str, str]:
        return renamed(key, text, flag)  # runtime/renamed.py's table

    @classmethod
    def of_saved(cls, values: Mapping[str, Any], where: str) -> MPCSettings:
        """The settings a run's config.json or a planner checkpoint saved (`where`), old names and values renamed."""
        return cls(**renamed_settings(values, where))


def _old_name(old: str, new: str) -> property:
    """`settings.own_radius`, read or set: the renamed field, with a DeprecationWarning (until 2.0)."""

    def get(self):
        return getattr(self, renamed(old, None, "MPCSettings")[0])

    def put(self, value):
        setattr(self, *renamed(old, value, "MPCSettings"))

    return property(get, put, doc=f"renamed {new}")


for _old, (_new, _) in RENAMED.items():
    if _new != _old:
        setattr(MPCSettings, _old, _old_name(_old, _new))
_init = MPCSettings.__init__


@functools.wraps(_init)
def _init_renamed(self, *args, **kwargs):  # `MPCSettings(own_radius=0.2)`: warned, renamed
    _init(self, *args, **renamed_settings(kwargs, "MPCSettings"))


MPCSettings.__init__ = _init_renamed


@dataclass
class MBPOSettings(FromText):
    """`train --algorithm mbpo`'s settings: SAC on real steps and on short rollouts of the ensemble (mbpo.py).

    SAC on real transitions and short rollouts of the ensemble branched from real states (Janner et al. 2019). The
    ensemble's own settings, and its refits every `refit_every` env steps, are `--mpc`'s; SAC's are `--sac`'s.
    """

    flag: ClassVar[str] = "--mbpo"

    # MBPO: 1 on most tasks; errors compound beyond a few.
    rollout_length: int = setting(1, "model steps per branch, 1 to 8 (at most --mpc horizon)")
    rollout_batch: int = setting(512, "branches per generation of rollouts")
    rollout_every: int = setting(96, "env steps (all workers) between generations (96: a day of one worker)")
    real_ratio: float = setting(0.1, "share of each SAC batch drawn from real transitions, within [0, 1] (MBPO: 0.05)")
    # `--algorithm sac`: 1; the model's data bear more.
    gradient_steps: int = setting(4, "SAC's updates per vector step (overrides --sac gradient_steps)")
    model_buffer: int = setting(100_000, "model transitions kept, newest first")
    # The ensemble's data (without --init-from, its first fit) and the first start states.
    record_days: int | None = setting(
        14,
        "days of the building's own controls recorded first where the run has no states to branch from (no "
        "--init-from, or a planner saved without its data; none: the episode length)",
    )
    pretrain_updates: int = setting(5_000, "SAC's updates on the model's rollouts alone, before its first real step")
    rail_k: float | None = setting(
        2.0, "K outside the band beyond which the planner steers a worker instead of SAC (none: off)"
    )

    def __post_init__(self):
        super().__post_init__()
        if not 1 <= self.rollout_length <= 8:
            raise ValueError(f"rollout_length {self.rollout_length}: 1 to 8 model steps")
        if not 0 <= self.real_ratio <= 1:
            raise ValueError(f"real_ratio {self.real_ratio}: within [0, 1]")
        if self.rollout_batch < 1 or self.rollout_every < 1 or self.model_buffer < 1:
            raise ValueError("rollout_batch, rollout_every and model_buffer: at least 1")
