"""One building's folder and its status.json: where each stage's outputs go and which stages are done, so a rerun of
the same command (or one after Ctrl-C) continues where the last one stopped and never redoes a finished stage."""

from __future__ import annotations

import datetime as dt
import json
import re
from dataclasses import dataclass
from pathlib import Path

from parallel_eplus import io

STATUS_FILE = "status.json"
STAGES = ("prepare", "periods", "own", "reset", "train", "learned", "choice", "export", "report")


def now_iso() -> str:
    return dt.datetime.now().astimezone().isoformat(timespec="seconds")


def short_name(source: Path) -> str:
    """A folder name for a model or spec: RefBldgStand-aloneRetailNew2004_Chicago -> stand-alone-retail (the DOE
    prototypes' names, as the prototypes study wrote them), anything else its file name's stem, lower-cased."""
    stem = source.stem
    if stem.startswith("RefBldg") and "New2004" in stem:
        core = stem.removeprefix("RefBldg").split("New2004")[0]
        return re.sub(r"(?<=[a-z])(?=[A-Z])", "-", core).lower()
    return re.sub(r"[^a-z0-9._-]+", "-", stem.lower()).strip("-") or "building"


@dataclass(frozen=True)
class BuildingFolder:
    """DIR (one building) or DIR/<name>/ (one of several): the spec, the runs, the evaluations, the report."""

    root: Path
    name: str
    source: Path  # the model or spec the user gave

    @property
    def status_path(self) -> Path:
        return self.root / STATUS_FILE

    @property
    def spec(self) -> Path:
        """The spec every command runs on: the starter with its recommended actions, or a copy of the user's."""
        return self.root / "spec.toml"

    @property
    def rule_spec(self) -> Path:
        """`spec` naming Guideline 36's reset as its rule (the reset's evaluation and the planner riding it)."""
        return self.root / "spec-reset.toml"

    @property
    def periods_dir(self) -> Path:
        return self.root / "periods"

    @property
    def runs(self) -> Path:
        return self.root / "runs"

    def evaluation(self, candidate: str, period: str) -> Path:
        return self.root / "eval" / candidate / period

    @property
    def results(self) -> Path:
        """Each test period's csv over every candidate (what the report reads)."""
        return self.root / "results"

    @property
    def logs(self) -> Path:
        return self.root / "logs"

    @property
    def controller(self) -> Path:
        return self.root / "controller"

    @property
    def report(self) -> Path:
        return self.root / "report.md"

    # -- status.json ----------------------------------------------------------------------------
    def status(self) -> dict:
        try:
            return json.loads(self.status_path.read_text())
        except (OSError, ValueError):
            return {"name": self.name, "source": str(self.source), "stages": {}, "spent_s": 0.0}

    def write_status(self, status: dict) -> dict:
        self.root.mkdir(parents=True, exist_ok=True)
        io.write_text(self.status_path, json.dumps(status, indent=1) + "\n")
        return status

    def stage(self, name: str) -> dict:
        return self.status().get("stages", {}).get(name, {})

    def done(self, name: str) -> bool:
        return self.stage(name).get("state") in ("done", "refused", "skipped")

    def answered(self, budget_minutes: float) -> bool:
        """Whether a rerun under this budget has nothing left to do: the report written under at least this budget
        and no stage failed or unfinished (a failed one is tried again; a larger budget may train further)."""
        stages = self.status().get("stages", {})
        report = stages.get("report", {})
        final = ("done", "refused", "skipped", "short")  # short: the same budget cannot fit it the next time either
        return (report.get("state") == "done" and float(report.get("budget_minutes", -1.0)) >= budget_minutes
                and all(s.get("state") in final for s in stages.values()))  # fmt: skip

    def set_stage(self, name: str, **fields) -> dict:
        """Merge `fields` into the stage's record (state: done, refused, skipped, failed, running)."""
        status = self.status()
        record = status.setdefault("stages", {}).setdefault(name, {})
        record.update(fields)
        if fields.get("state") in ("done", "refused", "skipped", "failed"):
            record["finished"] = now_iso()
        self.write_status(status)
        return record

    def add_spent(self, seconds: float) -> float:
        status = self.status()
        status["spent_s"] = round(float(status.get("spent_s", 0.0)) + seconds, 1)
        self.write_status(status)
        return status["spent_s"]
