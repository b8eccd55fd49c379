"""Module paths that moved in 1.1 (the regrouping into sub-packages), and their old names kept for one release.

Importing an old path (`parallel_eplus.buildings.tariff`, a spec's `controller = "parallel_eplus.buildings.rbc:..."`,
a pickle naming it) gives the module at its new path and a `DeprecationWarning` naming it; 2.0 removes the old
names. `MOVED` is the one table of moves: the finder below, `saved_models` and the CHANGELOG read it.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import importlib.util
import sys
import types
import warnings

REMOVED_IN = "2.0"

MOVED: dict[str, str] = {
    # buildings/: the spec, the model's copy, weather, pricing, scoring and the rules, each a folder
    "parallel_eplus.buildings.model": "parallel_eplus.buildings.datacenter",
    "parallel_eplus.buildings.spec": "parallel_eplus.buildings.spec.load",
    "parallel_eplus.buildings.spec_types": "parallel_eplus.buildings.spec.records",
    "parallel_eplus.buildings.spec_sections": "parallel_eplus.buildings.spec.sections",
    "parallel_eplus.buildings.check": "parallel_eplus.buildings.check.names",
    "parallel_eplus.buildings.reach": "parallel_eplus.buildings.check.reach",
    "parallel_eplus.buildings.idf_text": "parallel_eplus.buildings.idf.objects",
    "parallel_eplus.buildings.idf_prep": "parallel_eplus.buildings.idf.prepare",
    "parallel_eplus.buildings.takeover": "parallel_eplus.buildings.idf.takeover",
    "parallel_eplus.buildings.ventilation": "parallel_eplus.buildings.idf.ventilation",
    "parallel_eplus.buildings.loops": "parallel_eplus.buildings.idf.loops",
    "parallel_eplus.buildings.thermostat": "parallel_eplus.buildings.idf.thermostat",
    "parallel_eplus.buildings.survey": "parallel_eplus.buildings.starter.survey",
    "parallel_eplus.buildings.init": "parallel_eplus.buildings.starter.write",
    "parallel_eplus.buildings.init_air": "parallel_eplus.buildings.starter.air_side",
    "parallel_eplus.buildings.init_text": "parallel_eplus.buildings.starter.toml_text",
    "parallel_eplus.buildings.weather": "parallel_eplus.buildings.weather.files",
    "parallel_eplus.buildings.epw": "parallel_eplus.buildings.weather.epw",
    "parallel_eplus.buildings.forecast": "parallel_eplus.buildings.weather.forecast_features",
    "parallel_eplus.buildings.weather_forecast": "parallel_eplus.buildings.weather.forecast",
    "parallel_eplus.buildings.weather_noise": "parallel_eplus.buildings.weather.noise",
    "parallel_eplus.buildings.tariff": "parallel_eplus.buildings.pricing.tariff",
    "parallel_eplus.buildings.bill": "parallel_eplus.buildings.pricing.bill",
    "parallel_eplus.buildings.comfort": "parallel_eplus.buildings.scoring.comfort",
    "parallel_eplus.buildings.kpis": "parallel_eplus.buildings.scoring.kpis",
    "parallel_eplus.buildings.reward": "parallel_eplus.buildings.scoring.reward",
    "parallel_eplus.buildings.rbc": "parallel_eplus.buildings.rules.datacenter",
    "parallel_eplus.buildings.air_reset": "parallel_eplus.buildings.rules.air_reset",
    "parallel_eplus.buildings.own_margin": "parallel_eplus.buildings.rules.own_margin",
    "parallel_eplus.buildings.precool": "parallel_eplus.buildings.rules.precool",
    "parallel_eplus.buildings.on_demand": "parallel_eplus.buildings.rules.on_demand",
    "parallel_eplus.buildings.rule_settings": "parallel_eplus.buildings.rules.settings",
    # engine/: the pipes, where episodes come from (the processes among them), and the EnergyPlus side
    "parallel_eplus.engine.process": "parallel_eplus.engine.episodes.process",
    "parallel_eplus.engine.pipe": "parallel_eplus.engine.pipes.pipe",
    "parallel_eplus.engine.frames": "parallel_eplus.engine.pipes.frames",
    "parallel_eplus.engine.pipe_sweep": "parallel_eplus.engine.pipes.leftovers",
    "parallel_eplus.engine.spin": "parallel_eplus.engine.pipes.spin",
    "parallel_eplus.engine.at_exit": "parallel_eplus.engine.pipes.at_exit",
    "parallel_eplus.engine.fork": "parallel_eplus.engine.episodes.fork",
    "parallel_eplus.engine.prepared": "parallel_eplus.engine.episodes.prepared",
    "parallel_eplus.engine.supply": "parallel_eplus.engine.episodes.supply",
    "parallel_eplus.engine.warm_process": "parallel_eplus.engine.episodes.warm",
    "parallel_eplus.engine.eplus_callback": "parallel_eplus.engine.eplus_side.callback",
    "parallel_eplus.engine.bridge": "parallel_eplus.engine.eplus_side.bridge",
    "parallel_eplus.engine.native": "parallel_eplus.engine.eplus_side.native",
    "parallel_eplus.engine.native_handoff": "parallel_eplus.engine.eplus_side.handoff",
    "parallel_eplus.engine.fork_side": "parallel_eplus.engine.eplus_side.fork",
    # learning/model_based/: the numpy runtime `serve` runs, the model, control, the students, MBPO
    "parallel_eplus.learning.model_based.planner": "parallel_eplus.learning.model_based.runtime.planner",
    "parallel_eplus.learning.model_based.calendar": "parallel_eplus.learning.model_based.runtime.calendar",
    "parallel_eplus.learning.model_based.demand": "parallel_eplus.learning.model_based.runtime.demand",
    "parallel_eplus.learning.model_based.energy_weights": "parallel_eplus.learning.model_based.runtime.energy_weights",
    "parallel_eplus.learning.model_based.ensemble_graph": "parallel_eplus.learning.model_based.runtime.ensemble_graph",
    "parallel_eplus.learning.model_based.features": "parallel_eplus.learning.model_based.runtime.features",
    "parallel_eplus.learning.model_based.guard": "parallel_eplus.learning.model_based.runtime.guard",
    "parallel_eplus.learning.model_based.dynamics": "parallel_eplus.learning.model_based.model.dynamics",
    "parallel_eplus.learning.model_based.dataset": "parallel_eplus.learning.model_based.model.dataset",
    "parallel_eplus.learning.model_based.exogenous": "parallel_eplus.learning.model_based.model.exogenous",
    "parallel_eplus.learning.model_based.sources": "parallel_eplus.learning.model_based.model.sources",
    "parallel_eplus.learning.model_based.control": "parallel_eplus.learning.model_based.control.mpc",
    "parallel_eplus.learning.model_based.own_level": "parallel_eplus.learning.model_based.model.own_level",
    "parallel_eplus.learning.model_based.saved_planner": "parallel_eplus.learning.model_based.control.saved_planner",
    "parallel_eplus.learning.model_based.checkpoint": "parallel_eplus.learning.model_based.control.checkpoint",
    "parallel_eplus.learning.model_based.distill": "parallel_eplus.learning.model_based.students.distill",
    "parallel_eplus.learning.model_based.through_model": "parallel_eplus.learning.model_based.students.through_model",
    "parallel_eplus.learning.model_based.mbpo": "parallel_eplus.learning.model_based.mbpo.algorithm",
    "parallel_eplus.learning.model_based.mbpo_state": "parallel_eplus.learning.model_based.mbpo.state",
    "parallel_eplus.learning.model_based.model_buffer": "parallel_eplus.learning.model_based.mbpo.buffer",
    # deploy/: by the extra each part needs (serve, export, bacnet)
    "parallel_eplus.deploy.server": "parallel_eplus.deploy.serve.server",
    "parallel_eplus.deploy.runtime": "parallel_eplus.deploy.serve.runtime",
    "parallel_eplus.deploy.contract": "parallel_eplus.deploy.serve.contract",
    "parallel_eplus.deploy.planner_runtime": "parallel_eplus.deploy.serve.planner_runtime",
    "parallel_eplus.deploy.served_rule": "parallel_eplus.deploy.serve.served_rule",
    "parallel_eplus.deploy.export": "parallel_eplus.deploy.export.policy",
    "parallel_eplus.deploy.graph": "parallel_eplus.deploy.export.graph",
    "parallel_eplus.deploy.planner_export": "parallel_eplus.deploy.export.planner",
    "parallel_eplus.deploy.parity": "parallel_eplus.deploy.export.parity",
    "parallel_eplus.deploy.bacnet": "parallel_eplus.deploy.bacnet.app",
    "parallel_eplus.deploy.bacnet_device": "parallel_eplus.deploy.bacnet.device",
    "parallel_eplus.deploy.bacnet_planner": "parallel_eplus.deploy.bacnet.planner",
    "parallel_eplus.deploy.bacnet_supervisor": "parallel_eplus.deploy.bacnet.supervisor",
    "parallel_eplus.deploy.point_map": "parallel_eplus.deploy.bacnet.point_map",
}


def warn_moved(old: str, stacklevel: int = 3) -> None:
    warnings.warn(
        f"{old} moved to {MOVED[old]}; the old path is removed in {REMOVED_IN}",
        DeprecationWarning,
        stacklevel=stacklevel,
    )


class _Alias(importlib.abc.Loader):
    """The old path as a thin module: every attribute read from the new one, so classes stay the same objects."""

    def create_module(self, spec):
        return types.ModuleType(spec.name)

    def exec_module(self, module: types.ModuleType) -> None:
        new = importlib.import_module(MOVED[module.__name__])
        module.__getattr__ = lambda name: getattr(new, name)  # PEP 562: pickle's and `from … import` reads
        module.__doc__ = new.__doc__
        module.__path__ = getattr(new, "__path__", [])  # so that old sub-paths of a package resolve too
        warn_moved(module.__name__, stacklevel=5)


class _Finder(importlib.abc.MetaPathFinder):
    def find_spec(self, fullname, path, target=None):
        if fullname not in MOVED or is_package(fullname):
            return None  # not moved, or a package of its own now whose __init__ forwards (`forward` below)
        return importlib.machinery.ModuleSpec(fullname, _Alias())


def is_package(old: str) -> bool:
    """Whether a moved module's old path is a package now (buildings.spec, buildings.check, deploy.export, …)."""
    return any(new.startswith(old + ".") for new in MOVED.values())


def forward(package: str, name: str):
    """A package's `__getattr__` for the names the module at its path used to hold, with the deprecation warning.

    A name that is one of the package's own modules is left to the import system (`from package import module`).
    """
    if importlib.util.find_spec(f"{package}.{name}") is not None:
        raise AttributeError(name)
    module = importlib.import_module(MOVED[package])
    try:
        value = getattr(module, name)
    except AttributeError:
        raise AttributeError(f"module {package!r} has no attribute {name!r}") from None
    warnings.warn(
        f"{package}.{name} moved to {module.__name__}.{name}; the old path is removed in {REMOVED_IN}",
        DeprecationWarning,
        stacklevel=3,
    )
    setattr(sys.modules[package], name, value)  # warned once: `from package import name` reads it twice
    return value


def install() -> None:
    """Old paths resolve to their modules, with a warning (called once, on importing the package)."""
    if not any(isinstance(f, _Finder) for f in sys.meta_path):
        sys.meta_path.append(_Finder())
