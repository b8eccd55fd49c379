"""`train --algorithm mpc`'s settings: the model, the data it learns from and the planner (a plain dataclass)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from parallel_eplus.learning.settings import FromText


@dataclass
class MPCSettings(FromText):
    """The model-based learner's settings; saved in the run's config.json and in every planner checkpoint."""

    flag: ClassVar[str] = "--mpc"

    # The ensemble (dynamics.py): members, hidden layers, fitting.
    members: int = 5
    hidden: int = 64
    epochs: int = 30  # passes over the data at the first fit
    refit_epochs: int = 5  # at each refit of the Dyna loop (warm-started)
    learning_rate: float = 2e-3
    batch_size: int = 256
    # The data (sources.py, training/mpc.py): the building's own controls are recorded first (`record_days` per
    # training weather, None: the run's episode length), then `explore_steps` env steps replay them with an offset
    # walking toward random targets, then the planner acts; the model is refitted every `refit_every` env steps.
    record_days: int | None = None
    explore_steps: int = 2_000
    explore_increment: float = 0.15  # the walk's largest step per control step, normalized action units
    explore_offset: float = 2.0  # the targets' largest distance from the recorded action (2: the whole box)
    explore_hold: int = 32  # a target is held 4 to this many control steps
    refit_every: int = 2_000
    # The planner (planner.py): CEM over increments of the last action.
    horizon: int = 8  # control steps (8 x 15 min = 2 h)
    candidates: int = 256
    iterations: int = 3
    elites: int = 32
    shrink: float = 1.0  # each CEM iteration after the first tries this share of the last one's candidates (elites)
    # per control step, normalized action units (2: the whole range). A thermostat's setback-to-occupied jump spans
    # 1.5-1.7 of a prototype's range: below that the planner reaches it a step late (`MPC.own_jump`)
    max_increment: float = 0.15
    init_std: float = 0.1
    # The planner's actions stay within the range of each action in the data widened by this
    # much (normalized units): a model knows nothing beyond its data, and a planner fitted on the building's own
    # controls alone drove the data center out of EnergyPlus's range within 9 hours. The range grows with the
    # planner's own steps at each refit (Dyna), by up to this much each time.
    support_margin: float = 0.1
    comfort_weight: float | None = None  # None: the run's Lagrange multiplier (--comfort-target), else fixed
    # Per K of the members' spread in a zone temperature, per step (the energy term is ~1 per step). At 2 it
    # outweighed the data center's savings tenfold and held the planner at the built-in controls' corner (-2 %
    # in a 14-day pilot); at 0.2 the planner goes where its data are thin, learns there (Dyna), and saves 25 %.
    disagreement_weight: float = 0.2
    # The comfort term over the members: "mean" (their average violation), or "worst" (the largest: the band kept
    # if every member's prediction keeps it, a chance constraint from the ensemble's spread).
    comfort_risk: str = "mean"
    terminal_weight: float = 0.0  # the horizon's last step's comfort term counts 1 + this many times
    # Where a building scored against its own thermostats (`band = "thermostat"`) pays for comfort: "all" steps,
    # setbacks too (BOPTEST's total discomfort), or "occupied" steps only (its share in own bounds and occupied
    # K.h; calendar.py). At every step, the warehouse's planner heated at night against setbacks its own controls
    # droop 0.3 K below, which no occupied score counts.
    comfort_hours: str = "all"
    # What discomfort a candidate pays for: all of it beyond the bounds ("bound"), or only what exceeds the
    # discomfort the building's own thermostats would have from the same state, played through the same model
    # ("own"; calendar.own_reference). A zone its own controls cannot hold either (the warehouse's bulk storage,
    # which has no cooling) then costs nothing to leave as it is; against the bound, the planner cooled its
    # neighbours for it.
    comfort_reference: str = "bound"
    # What share in band the run's multiplier holds the planner to: `--comfort-target`'s ("target"), or where the
    # building's own controls kept less on the same dates and weathers, theirs ("own"; own_level.py). The
    # warehouse's own controls keep 77.6 % in summer: against 99.8 % its multiplier sat at its cap.
    comfort_level: str = "target"
    # With comfort_reference=own: leave the own plan only where every member of the ensemble predicts the chosen plan
    # costs less than it (the others' consensus). The search picks the candidate the model likes best, and on the
    # restaurants that was a plan its errors favoured: HVAC x1.018 where the own plan was a candidate all along.
    consensus: bool = False
    # With comfort_reference=own: leave the own plan only where the chosen plan's predicted cost over the horizon is
    # below the own plan's by at least this share of it (0: any saving). The search's best of hundreds of
    # candidates is the one the model's errors favour most (the optimizer's curse): on the full-service restaurant
    # the planner left its own thermostats' plan on 62-71 % of steps, by +/-1 K, for a predicted saving the
    # simulator did not pay out (gas +0.7 %, HVAC electricity +1 %, CO peak heating).
    min_saving: float = 0.0
    # With comfort_reference=own: each thermostat action kept within this much (normalized units) of the own plan's
    # at every step of a candidate (None: anywhere in its range). In the data the model learns from, a zone's
    # ventilation and heating start when its setpoint leaves the setback: held at the setback when the schedule
    # starts, the full-service restaurant's dining room fell 5 K in a step, where the model predicted 0.1 K
    # (docs/model-based.md). Off the own plan by a few tenths, the model has seen the building; by 6 K, it has not.
    own_radius: float | None = None
    # The model also sees whether the building is occupied at each step's end (the band applies: by date as the
    # calendar recorded it, else the weekly majority). In a restaurant's data a zone's ventilation and heating
    # start when its setpoint leaves the setback, always together: told only the setpoint, the model put the cold
    # air's arrival down to the setpoint and predicted 0.1 K for a 5 K fall (docs/model-based.md).
    occupancy_input: bool = False
    # With comfort_reference=own: the realised test for leaving the own plan (guard.py). A worker whose planner left
    # the own plan within the last `guard_steps` steps, and whose zones end a step more than this many K (summed over
    # zones, where the band applies) beyond the discomfort the model predicted for the own plan's step, plays the
    # own plan for the next `guard_steps` steps (None: no guard). The model's error off the own plan is not in its
    # predicted saving (min_saving=0.1 was not safe, docs/model-based.md); the building's reply is.
    guard_k: float | None = None
    guard_steps: int = 12
    # With comfort_reference=own: what a thermostat action may do where the band applies: anything the rest allows
    # ("free"), condition at least as much as the own plan ("at_least_own": a cooling setpoint no higher than its
    # own, a heating setpoint no lower), or follow the own plan ("own"). A zone sits at its thermostat's setpoint,
    # and its own setpoint is the bound: the quick-service restaurant's planner raised the dining room's cooling
    # setpoint 0.8 K above its own with the zone at 24.0 C, a move its data never showed, and the zone rose 0.3 K
    # past the bound (docs/model-based.md). Outside the band's hours the planner moves as before.
    band_thermostats: str = "free"
    # and this many steps before the band starts (as far as the horizon sees): the retail store's planner set back 0.6 K
    # deeper than its own at night, the zones met the morning's schedule 0.5 K colder, and its first occupied hour held
    # most of its excess K.h (docs/model-based.md). 0: from the band's first step.
    band_lead: int = 0
    # With comfort_reference=own: the own plan's thermostats this many K inside their own setpoints (heating higher,
    # cooling lower), the margin `OwnMargin` gives a rule. Five prototypes' planners ended 0.08-0.2 occupied K.h above
    # their own controls over 20 fortnights with each thermostat on its own plan (docs/model-based.md); EnergyPlus
    # holds a zone within 0.01 K of its setpoint. 0: at their own setpoints.
    own_margin: float = 0.0
    # With comfort_reference=own: where the own plan of an action no thermostat schedule sets comes from: what the
    # building's own controls set on that date ("building": the DOE VAV loops' constant 12.8 C), or the spec's rule
    # (its `controller`, `--rbc`), run beside the planner on each worker ("rule": Guideline 36's supply-air reset,
    # rules/air_reset.py). The actions the rule releases keep the building's plan. The planner then improves on
    # the rule, as the data center's best policy corrects its rule, where against the constant it was held within
    # `own_radius` of 12.8 C, far from where the reset saves (docs/model-based.md).
    own_plan: str = "building"
    noise: float = 0.0  # exploration added to the planner's action in training (normalized units)
    # Distillation (distill.py): the policy network fitted to the planner's own actions.
    distill: bool = True
    # The last share of the budget, DAgger (Ross et al. 2011): the distilled policy acts, the planner labels the
    # states it visits, and the policy is refitted on every label at each refit. A policy cloned on the planner's
    # own states alone drifted to 30 C in closed loop (2 % in band on CA). A worker more than 2 K outside the band
    # is steered by the planner meanwhile.
    dagger_share: float = 0.25
    # What the student learns from: "dagger" fits it to the planner's actions (distill.py); "gradient" clones it
    # once, then trains it on the planner's own cost through the model, from the states of the planner's steps
    # (through_model.py), at each refit of DAgger's phase and at the end. A six-sensor copy of the planner lost the
    # band on the paper's data center (78 %); the gradient student with the clock's features held 99.5 % in the
    # pilots (docs/model-based.md, "A network learned through the model").
    student: str = "dagger"
    student_updates: int = 1500  # gradient steps through the model at each refit and at the end
    student_batch: int = 256  # start states per step
    student_learning_rate: float = 3e-4
    student_comfort_weight: float = 1.0  # the comfort term's weight in the student's cost (the energy term ~1 a step)
    # The band the student keeps, shrunk by this much (K; None: the planner's --comfort-margin). A network acts on
    # a coarser view than its planner (no forecast, one action per state): on the paper's data center, trained
    # through the model at the planner's 0.5 K, seed 0's CO year held 99.56 % in band; at 0.6 K every seed and
    # weather held >= 99.64 % (docs/model-based.md, "A 0.6 K margin").
    student_margin: float | None = None

    def __post_init__(self):
        if self.comfort_hours not in ("all", "occupied"):
            raise ValueError(f"comfort_hours {self.comfort_hours!r}: 'all' or 'occupied'")
        if self.comfort_reference not in ("bound", "own"):
            raise ValueError(f"comfort_reference {self.comfort_reference!r}: 'bound' or 'own'")
        if self.comfort_level not in ("target", "own"):
            raise ValueError(f"comfort_level {self.comfort_level!r}: 'target' or 'own'")
        if self.comfort_risk not in ("mean", "worst"):
            raise ValueError(f"comfort_risk {self.comfort_risk!r}: 'mean' or 'worst'")
        if self.band_thermostats not in ("free", "at_least_own", "own"):
            raise ValueError(f"band_thermostats {self.band_thermostats!r}: 'free', 'at_least_own' or 'own'")
        if self.own_plan not in ("building", "rule"):
            raise ValueError(f"own_plan {self.own_plan!r}: 'building' or 'rule'")
        if self.student not in ("dagger", "gradient"):
            raise ValueError(f"student {self.student!r}: 'dagger' or 'gradient'")
        if not 0 < self.shrink <= 1:
            raise ValueError(f"shrink {self.shrink}: within (0, 1]")
        if self.own_radius is not None and not 0 <= self.own_radius <= 2:
            raise ValueError(f"own_radius {self.own_radius}: normalized units, within [0, 2]")
        if self.guard_k is not None and self.guard_k < 0:
            raise ValueError(f"guard_k {self.guard_k}: K beyond the own plan's predicted discomfort, >= 0")
        if not 0 <= self.own_margin <= 1:
            raise ValueError(f"own_margin {self.own_margin}: K inside the own setpoints, within [0, 1]")
        if self.band_lead < 0:
            raise ValueError(f"band_lead {self.band_lead}: steps before the band, >= 0")
        if self.guard_steps < 1:
            raise ValueError(f"guard_steps {self.guard_steps}: steps, >= 1")
        if self.student_margin is not None and self.student_margin <= 0:
            raise ValueError(f"student_margin {self.student_margin}: K inside the band, > 0")
        if not 0 <= self.min_saving < 1:
            raise ValueError(f"min_saving {self.min_saving}: a share of the own plan's cost, within [0, 1)")


@dataclass
class MBPOSettings(FromText):
    """`train --algorithm mbpo` (mbpo.py): SAC on real transitions and short rollouts of the ensemble branched from
    real states (Janner et al. 2019). The ensemble's own settings, and its refits every `refit_every` env steps,
    are `--mpc`'s."""

    flag: ClassVar[str] = "--mbpo"

    rollout_length: int = 1  # model steps per branch (MBPO: 1 on most tasks; errors compound beyond a few)
    rollout_batch: int = 512  # branches per generation
    rollout_every: int = 96  # env steps (all workers) between generations: a day of one worker
    real_ratio: float = 0.1  # share of each SAC batch drawn from real transitions (MBPO: 0.05)
    gradient_steps: int = 4  # SAC's updates per vector step (`--algorithm sac`: 1): the model's data bear more
    model_buffer: int = 100_000  # model transitions kept, newest first
    # Days of the building's own controls recorded first where the run has no states to branch from (no
    # --init-from, or a committed planner without its data): the ensemble's data (without --init-from, its first
    # fit) and the first start states. None: the run's episode length.
    record_days: int | None = 14
    pretrain_updates: int = 5_000  # SAC's updates on the model's rollouts alone, before its first real step
    rail_k: float | None = 2.0  # a worker with a zone this far outside the band is steered by the planner (None: off)

    def __post_init__(self):
        if not 1 <= self.rollout_length <= 8:
            raise ValueError(f"rollout_length {self.rollout_length}: 1 to 8 model steps")
        if not 0 <= self.real_ratio <= 1:
            raise ValueError(f"real_ratio {self.real_ratio}: within [0, 1]")
        if self.rollout_batch < 1 or self.rollout_every < 1 or self.model_buffer < 1:
            raise ValueError("rollout_batch, rollout_every and model_buffer: at least 1")
