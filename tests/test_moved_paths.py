"""Module paths from before the regrouping (parallel_eplus/_moved.py): each still imports, warning with its new path,
and gives the same objects, so user code, a spec's `controller` and pickles naming an old path keep working."""

from __future__ import annotations

import importlib
import json
import pickle
import subprocess
import sys

import pytest

from parallel_eplus._moved import is_package

_CHECK = """
import importlib, json, sys, warnings
from parallel_eplus._moved import MOVED
bad = {}
for old, new in MOVED.items():
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        module, target = importlib.import_module(old), importlib.import_module(new)
        names = [n for n in vars(target) if not n.startswith("_")]
        same = bool(names) and all(getattr(module, n) is getattr(target, n) for n in names)
    said = any(issubclass(x.category, DeprecationWarning) and new in str(x.message) for x in w)
    if not (same and said):
        bad[old] = {"same names": same, "warned": said}
print(json.dumps(bad))
"""


def test_every_old_path_imports_with_a_warning_naming_the_new_one():
    """In a fresh interpreter (this one may have imported old paths already): the warning, then the same objects."""
    done = subprocess.run([sys.executable, "-c", _CHECK], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    assert json.loads(done.stdout.splitlines()[-1]) == {}


def test_an_old_module_that_is_a_package_now_forwards_its_names():
    """`buildings.spec` was a module and is a package: its old names still read, with the warning, once."""
    package = importlib.import_module("parallel_eplus.buildings.spec")
    package.__dict__.pop("ActionSpec", None)  # warned once per process: another test may have read it
    with pytest.warns(DeprecationWarning, match="buildings.spec.load.ActionSpec"):
        from parallel_eplus.buildings.spec import ActionSpec
    from parallel_eplus.buildings.spec.records import ActionSpec as record

    assert ActionSpec is record
    from parallel_eplus.buildings.check import reach  # a module of the new package, no warning needed

    assert reach.__name__ == "parallel_eplus.buildings.check.reach"
    assert is_package("parallel_eplus.buildings.spec") and not is_package("parallel_eplus.buildings.tariff")


def test_a_pickle_naming_an_old_path_loads_as_the_new_class():
    from parallel_eplus.buildings.pricing.tariff import Tariff

    data = pickle.dumps(Tariff.__new__(Tariff), protocol=0).replace(  # protocol 0: names as text lines
        b"parallel_eplus.buildings.pricing.tariff", b"parallel_eplus.buildings.tariff"
    )
    with pytest.warns(DeprecationWarning):
        sys.modules.pop("parallel_eplus.buildings.tariff", None)
        assert type(pickle.loads(data)) is Tariff


def test_a_spec_controller_named_by_its_old_path_still_resolves():
    from parallel_eplus.buildings.rules.datacenter import RuleBasedController

    sys.modules.pop("parallel_eplus.buildings.rbc", None)
    with pytest.warns(DeprecationWarning, match="rules.datacenter"):
        old = importlib.import_module("parallel_eplus.buildings.rbc")
    assert old.RuleBasedController is RuleBasedController
