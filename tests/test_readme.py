"""The README's Python snippets run as written (real EnergyPlus, short run periods)."""

import json
import re
from pathlib import Path

import pytest

README = Path(__file__).resolve().parent.parent / "README.md"
SNIPPETS = re.findall(r"```python\n(.*?)```", README.read_text(), flags=re.S)


def test_readme_has_snippets():
    assert SNIPPETS, "README.md should show how to use the env from Python"


@pytest.mark.slow
@pytest.mark.parametrize("index", range(len(SNIPPETS)))
def test_readme_snippet_runs(index, tmp_path, monkeypatch, no_leaks):
    monkeypatch.chdir(tmp_path)
    exec(compile(SNIPPETS[index], f"README.md snippet {index}", "exec"), {"__name__": "__readme__"})


# ------------------------------------------------------------------------------------------------------------------
# Every figure in the README's "Where it stands" is read from a committed results file: each expected cell below is
# computed from that file and must be the README's, so a rerun that changes a result fails here until the README
# says so. (The paper's own row is the paper's figures, not ours.)
ROOT = README.parent
PAPER = ROOT / "results" / "paper" / "results.csv"
MB = ROOT / "results" / "model-based"
PROTOTYPES = ROOT / "results" / "prototypes"


def _signed(x: float) -> str:
    return f"{x:+.1f}".replace("-", "−")


def _cells(label: str) -> list[str]:
    """The README table row whose first cell is `label`: its cells, bold marks removed."""
    for line in README.read_text().splitlines():
        cells = [c.strip().replace("**", "") for c in line.strip().strip("|").split("|")]
        if line.startswith("|") and cells[0] == label:
            return cells
    raise AssertionError(f"README.md has no table row {label!r}")


def _mean_by_controller(path, column: str) -> dict[str, float]:
    import csv
    from collections import defaultdict

    values = defaultdict(list)
    with open(path) as f:
        for row in csv.DictReader(f):
            values[row["controller"]].append(float(row[column]))
    return {k: sum(v) / len(v) for k, v in values.items()}


def _seeds(path, controller: str, metric: str) -> tuple[float, float, float]:
    import csv

    with open(path) as f:
        for row in csv.DictReader(f):
            if (row["controller"], row["weather"], row["metric"]) == (controller, "all", metric):
                return float(row["mean"]), float(row["low"]), float(row["high"])
    raise AssertionError(f"{path}: no {controller} / all / {metric}")


def test_the_data_center_table_is_read_from_results_paper():
    power = _mean_by_controller(PAPER, "power_kw")
    in_band = _mean_by_controller(PAPER, "in_band_pct")
    rows = {
        "Built-in (EnergyPlus 25.2)": "Baseline",
        "Rule-based (`--rbc`)": "Rule-based",
        "the paper's method on 25.2: plain TRPO (CA-CO-FL), 10.5M steps": "TRPO (CA-CO-FL) 10.5M",
        "our best: TRPO correcting the rule-based controller's flow demand": "TRPO+RBC demand (CA-CO-FL)",
    }
    for label, controller in rows.items():
        p, base = power[controller], power["Baseline"]
        change = "" if controller == "Baseline" else f" ({_signed((p / base - 1) * 100).lstrip('+')} %)"
        assert _cells(label)[1:3] == [f"{p:.1f} kW{change}", f"{in_band[controller]:.2f} %"], label


def test_the_learned_table_is_read_from_the_seeds_files():
    rows = {  # (building, controller) -> (results folder, controller's label there, energy metric, prefix)
        ("the paper's data center", "planner (`--algorithm mpc`)"): (
            "datacenter-2zone/year-planner", "Planner", "energy_change_pct", ""),
        ("the paper's data center", "network trained through the model"): (
            "datacenter-2zone/year-train-gradient", "Through the model (train)", "energy_change_pct", ""),
        ("CRAC data center", "planner distilled into a network"): (
            "datacenter-crac/year", "Distilled", "energy_change_pct", ""),
        ("DOE small office", "planner"): ("office-small/year-planner", "Planner", "hvac_energy_change_pct", "HVAC "),
    }  # fmt: skip
    table = [line for line in README.read_text().splitlines() if line.startswith("| ")]
    for (building, controller), (folder, label, metric, prefix) in rows.items():
        (row,) = [[c.strip() for c in line.strip("|").split("|")] for line in table
                  if line.startswith(f"| {building} | {controller} |")]  # fmt: skip
        mean, low, high = _seeds(MB / folder / "seeds.csv", label, metric)
        assert row[2] == f"{prefix}{_signed(mean)} % [{_signed(low)}, {_signed(high)}]", row
        own = _mean_by_controller(MB / folder / "results.csv", "in_band_pct")["Baseline"]
        learned = _seeds(MB / folder / "seeds.csv", label, "in_band_pct")[0]
        assert row[3] == f"{own:.2f} % → {learned:.2f} %", row
        assert f"(results/model-based/{folder}/" in row[4], row


def test_the_claim_about_other_buildings_is_read_from_results_prototypes():
    import csv
    import re

    text = " ".join(README.read_text().split())
    # the portfolio (studies/portfolio) runs in chunks: until its 16 buildings are answered, the README says how far
    done = [
        s.parent.name
        for s in (ROOT / "results" / "optimize").glob("*/status.json")
        if json.loads(s.read_text()).get("stages", {}).get("report", {}).get("state") == "done"
    ]
    assert len(done) < 16, "the portfolio is complete: read the README's claim from results/optimize/summary.md"
    assert (
        f"`results/optimize/`, the 16 DOE prototypes through `optimize`'s defaults, runs in chunks "
        f"(studies/portfolio; {len(done)} of 16 answered so far)" in text
    )
    with open(PROTOTYPES / "prototypes.csv") as f:
        rows = list(csv.DictReader(f))
    saving = sum(min(float(r["hvac_energy_kwh"]), float(r["bill"])) <= 0.995 for r in rows)
    comfort = sum(float(r["occupied_discomfort_kh_learned"]) <= float(r["occupied_discomfort_kh_own"]) + 0.01
                  for r in rows)  # fmt: skip
    assert f"saves at least 0.5 % of HVAC energy or bill on {saving} of {len(rows)}" in text
    assert f"holds its own controls' comfort on {comfort};" in text
    # Guideline 36's reset: the table of results/prototypes/README.md (the study's report of its CSVs)
    report = (PROTOTYPES / "README.md").read_text()
    section = report.split("## The air side without learning")[1].split("\n## ")[0]
    ratios = [float(m) for m in re.findall(r"^\| [a-z-]+ \| ([0-9.]+) \|", section, flags=re.M)]
    big = sorted(r for r in ratios if r <= 0.95)
    assert all(r > 0.99 for r in ratios if r > 0.95)
    span = f"{(1 - big[-1]) * 100:.1f}–{(1 - big[0]) * 100:.1f} %"
    assert f"lowers HVAC energy by {span} on {len(big)} of the {len(ratios)} with air loops" in text
    assert f"under 1 % on the other {len(ratios) - len(big)}" in text


def test_the_bench_figures_are_read_from_results_bench():
    import json

    bench = json.loads((ROOT / "results" / "bench.json").read_text())
    text = " ".join(README.read_text().split())
    assert (
        f"EnergyPlus alone ran the data center's year in {bench['alone_s']:.1f} s and our env in {bench['env_s']:.1f} s"
        in text
    )
