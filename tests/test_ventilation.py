"""The outdoor air on demand (`ventilation = "demand"`, buildings/idf/ventilation.py): the DOE small office as the
EnergyPlus wheel ships it, one packaged unit per zone, each holding its outdoor air at the design occupancy's while
it runs. In the controller's copy each unit's air follows the people present; the building's own controls keep
the model as it is."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from parallel_eplus.buildings.idf.prepare import prepare_idf
from parallel_eplus.buildings.resources import spec_dir
from parallel_eplus.buildings.spec.load import SpecError, load_spec
from parallel_eplus.evaluation.controllers import BASELINE_LABEL, Controller
from parallel_eplus.evaluation.sweep import run_sweep

RULE = "parallel_eplus.buildings.rules.on_demand:OnDemand"
ROOT = Path(__file__).resolve().parents[1]
MEDIUM_PLANNER = ROOT / "results/model-based/office-medium/runs/office-medium-mpc-seed0/planner"  # committed
OUTDOOR_AIR = """
[[observations]]
name = "core_oa_kg_s"
variable = "Air System Outdoor Air Mass Flow Rate"
key = "PSZ-AC:1"
low = 0.0
high = 10.0
"""


def office(tmp_path: Path, ventilation: str = "demand") -> Path:
    text = (spec_dir() / "office-small.toml").read_text()
    path = tmp_path / "office-dcv.toml"
    path.write_text(text.replace('name = "office-small"', f'name = "office-dcv"\nventilation = "{ventilation}"', 1)
                    .replace("[reward]", OUTDOOR_AIR + "[reward]", 1))  # fmt: skip
    return path


def test_the_copy_gains_a_mechanical_ventilation_controller_per_unit_and_a_typo_is_named(tmp_path):
    spec = load_spec(office(tmp_path))
    report = prepare_idf(spec.idf, tmp_path / "model.idf", 1, ventilation=True)
    assert len(report.ventilation) == 5 and all("outdoor air on demand" in line for line in report.ventilation)
    assert "Core_ZN" in report.ventilation[0] and report.ventilation[0] in report.lines()
    text = (tmp_path / "model.idf").read_text(encoding="latin-1")
    assert text.count("Controller:MechanicalVentilation,") == 5
    assert "Controller:MechanicalVentilation" not in spec.idf.read_text(encoding="latin-1")
    assert not prepare_idf(spec.idf, tmp_path / "own.idf", 1).ventilation
    with pytest.raises(SpecError, match="ventilation: 'on demand' is not one of"):
        load_spec(office(tmp_path, "on demand"))
    import pyenergyplus.dataset as d  # the midrise apartment's units: outdoor air per zone, nothing to follow

    flats = Path(d.ref_models["midrise_apartment"])
    lines = prepare_idf(flats, tmp_path / "flats.idf", 1, ventilation=True).ventilation
    kept = [line for line in lines if "does not depend on people" in line]
    assert len(lines) == 24 and len(kept) == 23
    assert 'Controller:OutdoorAir "SPLITSYSTEMAC:01_OA_Controller" kept' in kept[0]


def test_the_outdoor_air_follows_the_people_and_the_own_controls_keep_theirs(tmp_path, no_leaks):
    """A January Wednesday in San Francisco: the office's occupancy schedule is 0.95 in the morning, 0.5 over
    lunch, 0.1 early in the evening and 0.05 later while its units run (07-22 h). Under its own controls the core
    unit's outdoor air is the same whenever they run; on demand it is that flow times the schedule, and the heating
    it saves shows."""
    from parallel_eplus.evaluation.scenarios import Period

    spec = office(tmp_path)
    base, demand = Controller(BASELINE_LABEL, "baseline"), Controller("on demand", "rbc", rule=RULE)
    assert demand.relinquishes(str(spec))
    day = Period("winter weekday", day=14, start_day=14, weekday="Wednesday", run_days=1, warmup_days=0)
    df = run_sweep([base, demand], ["CA"], 2, 2, tmp_path / "out", progress=False, building=str(spec),
                   periods={"CA": day})  # fmt: skip
    dirs = df.set_index("controller")["episode_dir"]
    steps = {c: pd.read_parquet(Path(d) / "steps.parquet").set_index("time") for c, d in dirs.items()}
    hour = steps[BASELINE_LABEL].index - pd.Timedelta(minutes=10)  # a step's flow is over the step before its time
    hour = hour.hour + hour.minute / 60
    own, dcv = steps[BASELINE_LABEL]["core_oa_kg_s"], steps["on demand"]["core_oa_kg_s"]
    morning, lunch = (hour >= 9) & (hour < 12), (hour >= 12) & (hour < 13)
    evening, late = (hour >= 18) & (hour < 20), (hour >= 20) & (hour < 22)
    design = own[morning].mean()
    assert design > 0.05 and own[morning | lunch | evening | late].between(0.98 * design, 1.02 * design).all()
    for when, share in ((morning, 0.95), (lunch, 0.5), (evening, 0.1), (late, 0.05)):
        assert dcv[when].between((share - 0.03) * design, (share + 0.03) * design).all(), (share, dcv[when])
    assert "Controller:MechanicalVentilation" in (Path(dirs["on demand"]) / "model.idf").read_text("latin-1")
    assert "Controller:MechanicalVentilation" not in (Path(dirs[BASELINE_LABEL]) / "model.idf").read_text("latin-1")
    hvac = df.set_index("controller")["hvac_energy_kwh"]
    assert hvac["on demand"] < 0.95 * hvac[BASELINE_LABEL]


def test_a_planner_acts_in_a_variant_of_its_building_and_nowhere_else(tmp_path, caplog, no_leaks):
    """A spec with the building's observations and actions but another copy (the medium office with its outdoor air
    on demand) takes the planners trained on the building, with a warning; another building still refuses them."""
    from parallel_eplus.learning.model_based.control.saved_planner import planner_controller

    planner = planner_controller(f"{MEDIUM_PLANNER}=Planner", "band_thermostats=own")
    variant = tmp_path / "office-medium-dcv.toml"
    text = (spec_dir() / "office-medium.toml").read_text()
    variant.write_text(text.replace('name = "office-medium"', 'name = "office-medium-dcv"\nventilation = "demand"', 1))
    df = run_sweep([planner], ["CA"], 1, 1, tmp_path / "out", progress=False, building=str(variant))
    assert "a variant with the same observations and actions" in caplog.text
    model = (Path(df.episode_dir.iloc[0]) / "model.idf").read_text(encoding="latin-1")
    assert model.count("Controller:MechanicalVentilation,") == 3  # one per floor's air loop
    with pytest.raises(ValueError, match="trained on building office-medium"):
        run_sweep([planner], ["CA"], 1, 1, tmp_path / "other", progress=False, building="office-small")
