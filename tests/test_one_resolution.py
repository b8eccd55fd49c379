"""A run resolves its building spec once: config, reward, weathers, envs and policy files all read that one object.

Each command resolves its building once (`load_building`: its spec read, its model's IDF parsed) and hands the
`Building` on; the counts below wrap the real functions (which still run) wherever a module imported them.
"""

from __future__ import annotations

import functools
import sys
import tomllib

import pandas as pd
import pytest

from parallel_eplus.buildings import building as building_module
from parallel_eplus.buildings import resources
from parallel_eplus.buildings.building import Building, load_building
from parallel_eplus.buildings.check import names
from parallel_eplus.buildings.idf import objects, prepare
from parallel_eplus.buildings.spec import load
from parallel_eplus.cli import main
from parallel_eplus.evaluation.controllers import BASELINE_LABEL, RBC_LABEL, policy_controller
from parallel_eplus.training.train import train

from .test_train import small_config


class Resolutions:
    """What resolving a building costs, counted while a command runs: specs read (`load_spec`), buildings resolved
    (`load_building` given a spec or None; given a `Building` it takes it as it is, nothing to count) and IDF texts
    parsed for them (`idf_objects`; not the parses of an episode's prepared copy, which parses the model it copies,
    nor of the spec's check, an EnergyPlus probe run once per spec, model and weather, then remembered on disk)."""

    def __init__(self, monkeypatch):
        # resolved afresh here, whatever an earlier test resolved in this process (the process's cache is restored)
        monkeypatch.setattr(building_module, "_load", functools.cache(building_module._load.__wrapped__))
        self.specs: list = []
        self.buildings: list = []
        self.parses = 0
        self._aside = 0  # inside a prepared copy or a check
        self._wrap(monkeypatch, load, "load_spec", lambda path, *a, **k: self.specs.append(path))
        self._wrap(monkeypatch, building_module, "load_building",
                   lambda path=None, *a, **k: isinstance(path, Building) or self.buildings.append(path))  # fmt: skip
        self._wrap(monkeypatch, objects, "idf_objects", lambda *a, **k: self._parsed())
        for module, name in ((prepare, "prepare_idf"), (names, "check_spec")):
            self._set_aside(monkeypatch, getattr(module, name), name)

    def _parsed(self) -> None:
        self.parses += not self._aside

    def _set_aside(self, monkeypatch, real, name: str) -> None:
        def aside(*args, **kwargs):
            self._aside += 1
            try:
                return real(*args, **kwargs)
            finally:
                self._aside -= 1

        self._everywhere(monkeypatch, name, real, aside)

    def _wrap(self, monkeypatch, module, name: str, count) -> None:
        real = getattr(module, name)

        def counted(*args, **kwargs):
            count(*args, **kwargs)
            return real(*args, **kwargs)

        self._everywhere(monkeypatch, name, real, counted)

    @staticmethod
    def _everywhere(monkeypatch, name: str, real, replacement) -> None:
        """`name` replaced in every loaded module that holds `real` under it (its own and each importer's)."""
        for module in list(sys.modules.values()):
            if getattr(module, "__dict__", {}).get(name) is real:
                monkeypatch.setattr(module, name, replacement)


@pytest.mark.slow
def test_evaluate_resolves_the_default_building_once(tmp_path, monkeypatch, no_leaks):
    """`evaluate --baseline --rbc`: the rule's check, both controllers, the sweep's check and every episode read the
    one `Building` the command resolved."""
    counted = Resolutions(monkeypatch)

    argv = ["evaluate", "--baseline", "--rbc", "--weathers", "CA", "--run-days", "1", "--workers", "2", "--quiet"]
    assert main([*argv, "--out", str(tmp_path)]) == 0

    assert counted.buildings == [None]  # the data center: its spec was read when the package was imported
    assert counted.specs == []
    assert counted.parses == 1  # its model's thermostats and own schedules, from one parse
    assert pd.read_csv(tmp_path / "results.csv").controller.tolist() == [BASELINE_LABEL, RBC_LABEL]


@pytest.mark.slow
def test_evaluate_resolves_a_named_building_once(tmp_path, monkeypatch, no_leaks):
    """`evaluate --building office-small`: the spec is read once, checked, and that object runs the sweep."""
    counted = Resolutions(monkeypatch)

    argv = ["evaluate", "--building", "office-small", "--baseline", "--weathers", "CA", "--run-days", "1", "--quiet"]
    assert main([*argv, "--out", str(tmp_path)]) == 0

    assert counted.buildings == ["office-small"]
    assert counted.specs == [resources.spec_file("office-small")]
    assert counted.parses == 1  # its thermostats (the reward's bounds) and its own schedules, from one parse


@pytest.mark.slow
def test_a_training_run_reads_its_spec_file_once(tmp_path, monkeypatch, no_leaks):
    text = (resources.spec_dir() / "datacenter-crac.toml").read_text()
    for key in ("idf", "baseline_idf"):  # models by absolute path: the spec lives outside the package
        name = text.split(f'\n{key} = "', 1)[1].split('"', 1)[0]
        text = text.replace(f'{key} = "{name}"', f'{key} = "{resources.model_file(name)}"', 1)
    spec = tmp_path / "crac.toml"
    spec.write_text(text)
    parses = []
    loads = tomllib.loads
    monkeypatch.setattr(tomllib, "loads", lambda s, **kw: parses.append(s == text) or loads(s, **kw))
    counted = Resolutions(monkeypatch)

    cfg = small_config(tmp_path, "once", building=str(spec), workers=1, weathers=["CA"], run_days=1,
                       timesteps=192, batch_size=96, checkpoint_every=96)  # fmt: skip
    model = train(cfg, progress=False)
    # `train` resolved it once (its check, config, workers and episode counts read that object)
    assert (counted.buildings, counted.specs, counted.parses) == ([str(spec)], [spec.resolve()], 1)
    controller = policy_controller(str(model))  # the policy files name the same spec: no second read

    assert parses.count(True) == 1
    assert controller.building == str(spec)
    assert load_building(spec) is load_building(str(spec))  # one object, whichever way it is named
