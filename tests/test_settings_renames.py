"""The planner's settings renamed in 1.1 (runtime/renamed.py's `RENAMED`): an old name or value works at every entry
(`--mpc` text, MPCSettings in Python, a run's config.json, a planner checkpoint, an exported contract's settings, a
sweep spec), warns naming the new one and 2.0, and the log says it once; what is written carries the new names."""

from __future__ import annotations

import json
import logging
import warnings
from dataclasses import asdict, fields
from pathlib import Path

import pytest

from parallel_eplus.learning.model_based.runtime import renamed as renamed_module
from parallel_eplus.learning.model_based.runtime.planner import PlannerSettings
from parallel_eplus.learning.model_based.runtime.renamed import RENAMED, renamed_settings
from parallel_eplus.learning.model_based.settings import MPCSettings
from parallel_eplus.learning.settings import _choices

ROOT = Path(__file__).resolve().parents[1]
# A committed run from before the renames: own_plan = "rule", comfort_reference and comfort_level "own".
RULED = ROOT / "results/model-based/office-medium/runs/office-medium-mpc-seed0"
OLD_TEXT = "own_plan=rule,comfort_reference=own,comfort_level=own,band_thermostats=at_least_own,own_radius=0.2," \
           "own_margin=0.1"  # fmt: skip
NEW = dict(baseline_source="rule", comfort_reference="baseline", comfort_level="baseline",
           band_thermostats="at_least_baseline", baseline_radius=0.2, baseline_margin=0.1)  # fmt: skip


@pytest.fixture(autouse=True)
def fresh_log():
    renamed_module._logged.clear()  # each test sees the log's first warning
    yield
    renamed_module._logged.clear()


def _new_of(settings) -> dict:
    return {k: getattr(settings, k) for k in NEW}


def test_the_table_names_settings_and_words_that_exist_now_and_none_that_went():
    hints = MPCSettings.hints()
    for old, (new, values) in RENAMED.items():
        assert new in hints and (old == new or old not in hints)
        assert set(values.values()) <= set(_choices(hints[new]))
        assert not set(values) & set(_choices(hints[new])) - set(values.values())  # no old word still means one


def test_old_names_and_values_in_mpc_text_warn_naming_the_new_one_and_2_0(caplog):
    caplog.set_level(logging.WARNING)
    with pytest.warns(DeprecationWarning) as caught:
        settings = MPCSettings.from_text(OLD_TEXT)
    assert _new_of(settings) == NEW
    messages = [str(w.message) for w in caught]
    assert any("own_radius is now baseline_radius" in m for m in messages)
    assert any("comfort_reference=own is now comfort_reference=baseline" in m for m in messages)
    assert any("band_thermostats=at_least_own is now band_thermostats=at_least_baseline" in m for m in messages)
    assert all("until 2.0" in m and m.startswith("--mpc") for m in messages)
    assert len(messages) == 6
    logged = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(logged) == 6 and all("until 2.0" in m for m in logged)
    with pytest.warns(DeprecationWarning):
        MPCSettings.from_text("own_radius=0.3,comfort_reference=own", flag="--planner")
    assert len([r for r in caplog.records if r.levelno == logging.WARNING]) == 6  # the log says each once


def test_new_names_and_old_words_otherwise_still_refused():
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the new names warn nothing
        settings = MPCSettings.from_text(",".join(f"{k}={v}" for k, v in NEW.items()))
    assert _new_of(settings) == NEW
    with pytest.raises(ValueError, match="comfort_reference='mine': one of 'band' or 'baseline'"):
        MPCSettings.from_text("comfort_reference=mine")
    with pytest.raises(ValueError, match="baseline_radius"), pytest.warns(DeprecationWarning):
        MPCSettings.from_text("own_radius=3")  # the range is checked under the new name


def test_python_keywords_attributes_and_values_from_before_warn_and_map():
    with pytest.warns(DeprecationWarning, match="own_margin is now baseline_margin"):
        settings = MPCSettings(own_margin=0.3, comfort_reference="own")
    assert (settings.baseline_margin, settings.comfort_reference) == (0.3, "baseline")
    with pytest.warns(DeprecationWarning, match="own_plan is now baseline_source"):
        assert settings.own_plan == "building"
    with pytest.warns(DeprecationWarning, match="own_radius is now baseline_radius"):
        settings.own_radius = 0.5
    assert settings.baseline_radius == 0.5


def test_written_settings_carry_the_new_names_only():
    from parallel_eplus.training.config import TrainConfig

    saved = json.loads(TrainConfig(algorithm="mpc", mpc=MPCSettings(**NEW)).to_json())["mpc"]
    assert not set(saved) & {old for old, (new, _) in RENAMED.items() if old != new}
    assert {k: saved[k] for k in NEW} == NEW
    planner = asdict(PlannerSettings.of(MPCSettings(**NEW)))  # an export's contract writes these fields
    assert "baseline_radius" in planner and "baseline_margin" in planner and "own_radius" not in planner


def test_a_committed_config_json_with_the_old_names_loads_with_the_new():
    from parallel_eplus.training.config import TrainConfig

    text = (RULED / "config.json").read_text()
    assert '"own_plan": "rule"' in text and '"comfort_reference": "own"' in text  # as 1.0 wrote it
    with pytest.warns(DeprecationWarning, match="config.json: the setting own_plan is now baseline_source"):
        cfg = TrainConfig.from_json(text)
    assert (cfg.mpc.baseline_source, cfg.mpc.comfort_reference, cfg.mpc.comfort_level) == ("rule", "baseline",
                                                                                           "baseline")  # fmt: skip
    resaved = json.loads(cfg.to_json())["mpc"]
    assert "own_plan" not in resaved and resaved["comfort_reference"] == "baseline"


def test_a_committed_planner_with_the_old_names_loads_and_plans_on_its_baseline():
    from parallel_eplus.learning.model_based.control.mpc import MPC

    with pytest.warns(DeprecationWarning, match="planner checkpoint"):
        mpc = MPC.load(RULED / "planner" / "planner.pt")
    assert (mpc.settings.baseline_source, mpc.settings.comfort_reference) == ("rule", "baseline")
    assert mpc.planner.settings.baseline_radius == mpc.settings.baseline_radius
    assert "own_plan" not in mpc.state()["settings"]  # saved again: the new names


def test_an_exported_contracts_old_settings_serve_with_the_new():
    old = {"horizon": 8, "candidates": 64, "iterations": 2, "elites": 8, "max_increment": 0.5, "init_std": 0.1,
           "disagreement_weight": 0.2, "own_radius": 0.1, "own_margin": 0.2, "band_thermostats": "own"}  # fmt: skip
    with pytest.warns(DeprecationWarning, match="a contract: the setting own_radius is now baseline_radius"):
        settings = PlannerSettings.of(old)
    assert (settings.baseline_radius, settings.baseline_margin, settings.band_thermostats) == (0.1, 0.2, "baseline")
    with pytest.warns(DeprecationWarning):
        both = renamed_settings({"own_radius": 0.1, "baseline_radius": 0.3}, "x")
    assert both == {"baseline_radius": 0.3}  # where both are given, the new name counts
    names = {f.name for f in fields(PlannerSettings)}
    assert not names & {old for old, (new, _) in RENAMED.items() if old != new}


def test_a_served_contracts_comfort_reference_from_before_is_read_as_now():
    from parallel_eplus.learning.model_based.runtime.renamed import renamed

    with pytest.warns(DeprecationWarning, match="comfort_reference=own is now comfort_reference=baseline"):
        assert renamed("comfort_reference", "own", "a contract") == ("comfort_reference", "baseline")
    with pytest.warns(DeprecationWarning, match="comfort_reference=bound is now comfort_reference=band"):
        assert renamed("comfort_reference", "bound", "a contract")[1] == "band"


def test_a_sweep_spec_with_the_old_names_is_read_with_the_new(tmp_path):
    from parallel_eplus.experiments.sweep_spec import load_spec

    spec = tmp_path / "sweep.toml"
    spec.write_text('[train]\nalgorithm = "mpc"\n[train.mpc]\nown_radius = 0.2\ncomfort_reference = "own"\n'
                    '[grid]\n"mpc.band_thermostats" = ["free", "own"]\n')  # fmt: skip
    with pytest.warns(DeprecationWarning, match="a sweep spec"):
        loaded = load_spec(spec)
    assert loaded.base["mpc.baseline_radius"] == 0.2 and loaded.base["mpc.comfort_reference"] == "baseline"
    assert loaded.grid == {"mpc.band_thermostats": ["free", "baseline"]}


def test_the_shipped_presets_use_the_new_names():
    from parallel_eplus.presets.catalog import load_preset, names

    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)
        for name in names():
            preset = load_preset(name)
            if "mpc" in preset.defaults("train"):
                MPCSettings.from_text(preset.defaults("train")["mpc"])
            if "planner" in preset.defaults("evaluate"):
                MPCSettings.from_text(preset.defaults("evaluate")["planner"])


def test_the_changelog_lists_every_rename():
    unreleased = (ROOT / "CHANGELOG.md").read_text().split("## Unreleased")[1].split("\n## ")[0]
    for old, (new, values) in RENAMED.items():
        if old != new:
            assert f"`{old}` → `{new}`" in unreleased
        for was, now in values.items():
            line = next(line for line in unreleased.splitlines() if f"`{new}=" in line and "→" in line)
            assert was in line and now in line
