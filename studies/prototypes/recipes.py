"""The training recipes the prototypes study has tried, in order (`prototypes.py run --recipe NAME`): each one the
last plus what the last one's diagnosis asked for (docs/model-based.md)."""

# The recipe for a building nobody tuned (the office's, docs/model-based.md): comfort held at its own controls'
# level in its own bounds, HVAC energy the objective, the clock observed, the morning's setpoint jump in one step.
# The planner is the controller scored: no policy distilled from it.
PLANNER = "max_increment=1.0,horizon=12,distill=false"
# A thermostat's jump from setback to occupied can span most of its action's range (the restaurants' heating:
# 15.6 -> 21 C of 15-21.5, 1.66 in normalized units): `max_increment=2.0` lets any candidate, and the own plan the
# planner pays beyond, make it in one step, as the building's own controls do.
JUMP = "max_increment=2.0,horizon=12,distill=false"
COMMON = ["--algorithm", "mpc", "--objective", "hvac", "--time-features", "--comfort-target", "99.8",
          "--checkpoint-every", "5000"]  # fmt: skip
RECIPES = {
    # the first: year-long episodes from January 1 (35k steps: about four months of each training weather), a
    # margin of 0.1 K inside the bounds
    "january": ["--run-days", "365", "--comfort-margin", "0.1", "--mpc", PLANNER, *COMMON],
    # the warehouse's diagnosis (docs/model-based.md): fortnights from random days (every season, where the first
    # never saw summer) and a twentieth of a kelvin's margin (its own controls sit on the bounds: 0.1 K cost heating)
    "seasons": ["--run-days", "14", "--random-start", "--comfort-margin", "0.05", "--mpc", PLANNER, *COMMON],
    # and the thermostat's bounds paid for in occupied hours only (`comfort_hours=occupied`, the hours its share in
    # own bounds and occupied K.h count): at every step, the warehouse's planner heated against night setbacks
    "occupied": [
        "--run-days",
        "14",
        "--random-start",
        "--comfort-margin",
        "0.05",
        "--mpc",
        f"{PLANNER},comfort_hours=occupied",
        *COMMON,
    ],
    # and only the discomfort beyond its own thermostats' plan paid for, that plan always a candidate
    # (`comfort_reference=baseline`): the warehouse's planner cooled the storage for a zone with no cooling
    "own": [
        "--run-days",
        "14",
        "--random-start",
        "--comfort-margin",
        "0.05",
        "--mpc",
        f"{PLANNER},comfort_hours=occupied,comfort_reference=baseline",
        *COMMON,
    ],
    # and the multiplier holding it to its own controls' share in band where that is below the target, date by
    # date (`comfort_level=baseline`): the warehouse's own controls keep 78 % in summer, and against 99.8 % its
    # multiplier sat at its cap
    "level": [
        "--run-days",
        "14",
        "--random-start",
        "--comfort-margin",
        "0.05",
        "--mpc",
        f"{PLANNER},comfort_hours=occupied,comfort_reference=baseline,comfort_level=baseline",
        *COMMON,
    ],
    # and the morning's jump in one step (JUMP): at 1.0 a step, the restaurants' planners reached the occupied
    # setpoint a step late, and so did the own plan it pays beyond, so the first occupied step's discomfort was
    # free: the quick-service restaurant's first occupied hour held 170 of its 227 zone K.h (docs/model-based.md)
    "jump": [
        "--run-days",
        "14",
        "--random-start",
        "--comfort-margin",
        "0.05",
        "--mpc",
        f"{JUMP},comfort_hours=occupied,comfort_reference=baseline,comfort_level=baseline",
        *COMMON,
    ],
    # and the own plan unless every member of the ensemble prefers the search's (`consensus`): the quick-service
    # restaurant's jump planner, evaluated so, went from HVAC x1.014-1.017 to x1.001-1.006 (docs/model-based.md)
    "consensus": [
        "--run-days",
        "14",
        "--random-start",
        "--comfort-margin",
        "0.05",
        "--mpc",
        f"{JUMP},comfort_hours=occupied,comfort_reference=baseline,comfort_level=baseline,consensus=true",
        *COMMON,
    ],
    # and the planner held near its own thermostats' plan (`baseline_radius=0.2`: the model knows the building only
    # there; held at the setback as the schedule starts, the full-service restaurant's dining room fell 5 K where the
    # model predicted 0.1 K) and off it only for a predicted 3 % or more over the horizon (`min_saving=0.03`: the
    # search's best of 256 candidates is the one the model's errors favour most): on the full-service restaurant's
    # `jump` planner, evaluated so, CA peak heating went from HVAC x1.045 at 3.37 occupied K.h (own 0.08) to x1.005
    # at 0.36, FL peak cooling from x1.014 at 18.2 K.h (own 18.4) to x1.003 at 18.5 (docs/model-based.md)
    "hedged": [
        "--run-days",
        "14",
        "--random-start",
        "--comfort-margin",
        "0.05",
        "--mpc",
        f"{JUMP},comfort_hours=occupied,comfort_reference=baseline,comfort_level=baseline,"
        "baseline_radius=0.2,min_saving=0.03",
        *COMMON,
    ],
    # `hedged` on Guideline 36's reset (`baseline_source=rule`; the spec names the rule as its `controller`,
    # `ON_RULE`): the supply air's baseline is the reset run beside the planner, not the building's constant 12.8 C,
    # so `baseline_radius` and `min_saving` hold the search near the reset. The offices' pilots: HVAC x0.928 and
    # x0.925 at no more occupied discomfort, where `hedged` on the building's own baseline found 0.4 %
    # (results/prototypes/ruled/)
    "hedged-rule": [
        "--run-days",
        "14",
        "--random-start",
        "--comfort-margin",
        "0.05",
        "--mpc",
        f"{JUMP},comfort_hours=occupied,comfort_reference=baseline,comfort_level=baseline,"
        "baseline_radius=0.2,min_saving=0.03,baseline_source=rule",
        *COMMON,
    ],
    # `hedged` and `hedged-rule` trained in the copy with the outdoor air on demand (IN_DEMAND; the spec `prototypes.py
    # ventilation` scores the measure alone on, `ventilation = "demand"`): each outdoor-air controller's flow follows
    # the people present, so the model learns the building that copy is, and the saving scored is a learned
    # controller's, not a rule's (the small office on demand alone: HVAC x0.826 at 5.9 occupied K.h, own 5.8)
    "hedged-demand": [
        "--run-days",
        "14",
        "--random-start",
        "--comfort-margin",
        "0.05",
        "--mpc",
        f"{JUMP},comfort_hours=occupied,comfort_reference=baseline,comfort_level=baseline,"
        "baseline_radius=0.2,min_saving=0.03",
        *COMMON,
    ],
    "hedged-rule-demand": [
        "--run-days",
        "14",
        "--random-start",
        "--comfort-margin",
        "0.05",
        "--mpc",
        f"{JUMP},comfort_hours=occupied,comfort_reference=baseline,comfort_level=baseline,"
        "baseline_radius=0.2,min_saving=0.03,baseline_source=rule",
        *COMMON,
    ],
    # and the model told whether the building is occupied at each step (`occupancy_input=true`, the calendar's by
    # date): in the restaurants' data the ventilation's start and the setpoint's jump always coincide, and the model
    # put the cold air's arrival down to the setpoint (a 5 K fall predicted at 0.1 K, docs/model-based.md)
    "occupancy": [
        "--run-days",
        "14",
        "--random-start",
        "--comfort-margin",
        "0.05",
        "--mpc",
        f"{JUMP},comfort_hours=occupied,comfort_reference=baseline,comfort_level=baseline,"
        "baseline_radius=0.2,min_saving=0.03,occupancy_input=true",
        *COMMON,
    ],
}

# Recipes that play another recipe's trained planners with other settings (`evaluate --planner`), no new training:
# (the trained recipe, its work folder's, and the settings). `banded`: `hedged`'s planners with each thermostat on
# the baseline wherever its band applies (`band_thermostats=baseline`): the planner moves the rest (supply air, where
# it takes it over) and the thermostats outside the occupied hours. The restaurants' and the medium office's discomfort
# came from moves off the own plan in occupied hours (a cooling setpoint 0.8 K above its own with the zone at the
# bound); played so, each held its own controls' occupied K.h on the pilots' fortnights (docs/model-based.md).
# `ruled`: `hedged-rule`'s planners so (the thermostats on their own plan, the supply air near the reset).
# `banded-margin`: `banded` with the baseline 0.02 K inside each own setpoint (`baseline_margin`), for the five
# buildings whose `banded` planner ended 0.08-0.2 occupied K.h above its own controls (docs/model-based.md).
PLAYED = {
    "banded": ("hedged", "band_thermostats=baseline"),
    "ruled": ("hedged-rule", "band_thermostats=baseline"),
    "banded-demand": ("hedged-demand", "band_thermostats=baseline"),
    "ruled-demand": ("hedged-rule-demand", "band_thermostats=baseline"),
    "banded-margin": ("hedged", "band_thermostats=baseline,baseline_margin=0.02"),
}

# Recipes trained on a spec naming Guideline 36's reset as its rule (`spec-rule.toml`), so only on the buildings whose
# starter takes over air loops; the others keep `FALLBACK`'s row (the same planner: no air side to ride).
RULE = "parallel_eplus.buildings.rules.air_reset:SupplyAirReset"
# The building's own controls with the outdoor air on demand (`ventilation = "demand"`): `prototypes.py ventilation`
ON_DEMAND = "parallel_eplus.buildings.rules.on_demand:OnDemand"
# ... and each thermostat 0.02 K inside its own schedule, where every action has one (the comfort the measure costs,
# bought back)
MARGIN = "parallel_eplus.buildings.rules.own_margin:OwnMargin"
ON_RULE = {"hedged-rule", "hedged-rule-demand"}
# Recipes trained in the copy with the outdoor air on demand, so only where the model holds a fixed minimum of it; the
# others keep `FALLBACK`'s row too.
IN_DEMAND = {"hedged-demand", "hedged-rule-demand"}
FALLBACK = "banded"
# The played recipes with tables of their own (RECIPE/ in the main one): every one but FALLBACK, which is the main one
OTHERS = [name for name in PLAYED if name != FALLBACK]
