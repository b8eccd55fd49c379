"""A run resolves its building spec once: config, reward, weathers, envs and policy files all read that one object."""

from __future__ import annotations

import tomllib

import pytest

from parallel_eplus.buildings import resources
from parallel_eplus.buildings.building import load_building
from parallel_eplus.evaluation.controllers import policy_controller
from parallel_eplus.training.train import train

from .test_train import small_config


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

    cfg = small_config(tmp_path, "once", building=str(spec), workers=1, weathers=["CA"], run_days=1,
                       timesteps=192, batch_size=96, checkpoint_every=96)  # fmt: skip
    model = train(cfg, progress=False)
    controller = policy_controller(str(model))  # the policy files name the same spec: no second read

    assert parses.count(True) == 1
    assert controller.building == str(spec)
    assert load_building(spec) is load_building(str(spec))  # one object, whichever way it is named
