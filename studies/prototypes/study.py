"""The study's layout: where each building's runs, evaluations and status live, and which prototypes there are."""

from __future__ import annotations

import fcntl
import json
import re
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from recipes import IN_DEMAND, MARGIN, ON_DEMAND, ON_RULE, RULE

SCENARIOS = ("peak_heat", "typical_heat", "peak_cool", "typical_cool")  # BOPTEST's, each evaluated


@dataclass(frozen=True)
class Study:
    """Where the study works and what each run costs."""

    work: Path
    out: Path
    steps: int = 35_000  # env steps per run
    workers: int = 2
    seeds: tuple[int, ...] = (0,)
    recipe: str = "hedged"  # what it trains (RECIPES)
    played: str = ""  # the recipe it scores, where it plays the trained planners with other settings (PLAYED)
    fallback: Path | None = None  # FALLBACK's table, whose rows stand where the recipe does not apply (`applies`)

    def folder(self, name: str) -> Path:
        return self.work / name

    def run_dir(self, name: str, seed: int) -> Path:
        return self.work / name / "runs" / f"{name}-mpc-seed{seed}"


def models() -> list[Path]:
    from parallel_eplus.buildings.resources import model_file

    return sorted(model_file("RefBldgSmallOfficeNew2004_Chicago.idf").parent.glob("RefBldg*.idf"))


def short_name(model: Path) -> str:
    """RefBldgStand-aloneRetailNew2004_Chicago -> stand-alone-retail."""
    core = model.stem.removeprefix("RefBldg").split("New2004")[0]
    return re.sub(r"(?<=[a-z])(?=[A-Z])", "-", core).lower()


@contextmanager
def claimed(study: Study, name: str) -> Iterator[bool]:
    """Whether this process has the building to itself: two `run`s over overlapping names would train one run folder."""
    study.folder(name).mkdir(parents=True, exist_ok=True)
    with open(study.folder(name) / ".run.lock", "w") as lock:
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            yield False
            return
        yield True  # released when the file closes, or with the process


def status_file(study: Study, name: str) -> Path:
    return study.folder(name) / "status.json"


def read_status(study: Study, name: str) -> dict:
    path = status_file(study, name)
    return json.loads(path.read_text()) if path.is_file() else {"name": name}


def write_status(study: Study, name: str, **fields) -> dict:
    status = read_status(study, name) | fields
    study.folder(name).mkdir(parents=True, exist_ok=True)
    status_file(study, name).write_text(json.dumps(status, indent=1) + "\n")
    return status


def finished(run: Path) -> bool:
    try:
        return json.loads((run / "status.json").read_text()).get("state") == "finished"
    except (OSError, ValueError):
        return False


def applies(study: Study, name: str) -> bool:
    """Whether the recipe has something to train on: an air loop's reset to ride (ON_RULE), outdoor air to put on
    demand (IN_DEMAND)."""
    status = read_status(study, name)
    if study.recipe in ON_RULE and not status.get("supply_air_loops"):
        return False
    return study.recipe not in IN_DEMAND or bool(demand_controllers(study, name))


def demand_controllers(study: Study, name: str) -> int:
    """How many outdoor-air controllers the copy with the outdoor air on demand changes (buildings/idf/ventilation.py),
    kept in the building's status.json."""
    status = read_status(study, name)
    if "demand_controllers" not in status:
        from parallel_eplus.buildings.idf.objects import idf_objects
        from parallel_eplus.buildings.idf.ventilation import plan_ventilation

        text = next(m for m in models() if short_name(m) == name).read_text(encoding="latin-1")
        status = write_status(study, name, demand_controllers=len(plan_ventilation(text, idf_objects(text)).added))
    return status["demand_controllers"]


def results_folder(study: Study, name: str) -> Path:
    """Where a building's scenario csvs are: the recipe's, or the fallback's where the recipe does not apply."""
    if study.fallback and not applies(study, name):
        return study.fallback / name
    return study.out / name


def scored(study: Study, name: str) -> bool:
    return all((results_folder(study, name) / f"{s}.csv").is_file() for s in SCENARIOS)


def rule_spec(study: Study, name: str) -> Path:
    """The starter's spec with Guideline 36's reset named as its rule (`spec-rule.toml`), written from the starter's
    so the two never drift."""
    ruled = study.folder(name) / "spec-rule.toml"
    text = (study.folder(name) / "spec.toml").read_text()
    text = re.sub(r"^(idf = .*)$", rf'\1\ncontroller = "{RULE}"', text, count=1, flags=re.M)
    if not ruled.is_file() or ruled.read_text() != text:  # unchanged: a run reading it meanwhile is never disturbed
        ruled.write_text(text)
    return ruled


# The measures in the copy with the outdoor air on demand (OUT/<name>/<folder>/, `prototypes.py ventilation`): the
# rule each one's spec names
DEMAND_RULES = {"ventilation": ON_DEMAND, "rule-ventilation": RULE, "margin-ventilation": MARGIN}


def demand_spec(study: Study, name: str, measure: str = "ventilation") -> Path:
    """The starter's spec with its outdoor air on demand (`ventilation = "demand"`, the starter's offer) and the
    measure's rule (DEMAND_RULES): every action released to the building's own controls (`spec-ventilation.toml`),
    Guideline 36's reset (`spec-rule-ventilation.toml`) or the thermostats a margin inside their own schedules
    (`spec-margin-ventilation.toml`), written from the starter's."""
    spec = study.folder(name) / f"spec-{measure}.toml"
    text = (study.folder(name) / "spec.toml").read_text()
    demand = f'ventilation = "demand"\ncontroller = "{DEMAND_RULES[measure]}"'
    text = re.sub(r"^(idf = .*)$", lambda m: f"{m.group(1)}\n{demand}", text, count=1, flags=re.M)
    if not spec.is_file() or spec.read_text() != text:
        spec.write_text(text)
    return spec


def own_schedules(spec: Path) -> bool:
    """Whether every action of `spec` has a schedule of the building's own (what OwnMargin corrects)."""
    from parallel_eplus.buildings.building import load_building

    return all(all(own) for own in load_building(str(spec)).own)


def spec_of(study: Study, name: str) -> Path:
    """The spec a recipe trains and scores on: the starter's, the one naming the reset (ON_RULE), or either with the
    outdoor air on demand (IN_DEMAND: the spec `prototypes.py ventilation` scores the measure alone on)."""
    if study.recipe in IN_DEMAND:
        return demand_spec(study, name, "rule-ventilation" if study.recipe in ON_RULE else "ventilation")
    return rule_spec(study, name) if study.recipe in ON_RULE else study.folder(name) / "spec.toml"
