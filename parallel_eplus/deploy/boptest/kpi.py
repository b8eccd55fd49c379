"""`GET /kpi`: BOPTEST's core KPIs from the test's steps since its start time (the warm-up left out), computed by
the same summary `evaluate` writes (engine/episode.py, buildings/scoring/): the figures equal evaluate's for the same
steps, with the electricity price of the test's scenario.

| BOPTEST | here (summary key) |
| --- | --- |
| tdis_tot, K·h/zone | discomfort_kh: each zone's ∫ distance outside its bounds, averaged over the zones |
| idis_tot, ppm·h/zone | null: no building here models CO2 |
| ener_tot, kWh/m² | hvac_energy_kwh_m2: HVAC energy over every fuel |
| cost_tot, $/m² | cost_m2: HVAC energy × the scenario's electricity price (other fuels at the spec's) |
| emis_tot, kg CO2e/m² | emissions_kg_m2 |
| pele_tot, pgas_tot, pdih_tot, kW/m² | the highest control-step mean HVAC power of the fuel; null where it has none |
| time_rat | the mean of (time between advances) / step, as BOPTEST computes it; null before two advances |

Incremental (`Totals`): each figure is a sum over the steps (tdis too: the zones' mean of each zone's sum is the sum,
over chunks of steps, of the zones' means) or a highest value, so the summary of the steps new since the last `/kpi`,
folded into running totals, gives the summary's figures over every step, to float rounding: a request costs its new
steps, not the episode. The summary stays the one place each figure's formula lives; `Totals` adds and takes maxima.
"""

from __future__ import annotations

import dataclasses

import pandas as pd

from parallel_eplus.buildings.scoring.kpis import per_area
from parallel_eplus.engine.episode import summarize

CORE = ("tdis_tot", "idis_tot", "ener_tot", "cost_tot", "emis_tot", "pele_tot", "pgas_tot", "pdih_tot", "time_rat")
PEAKS = {"pele_tot": ("electricity",), "pgas_tot": ("naturalgas", "gas"), "pdih_tot": ("districtheating",)}
SUMS = ("discomfort_kh", "hvac_energy_kwh", "cost", "emissions_kg")  # the summary's figures the KPIs read, summed


def scenario_comfort(comfort, tariff):
    """The building's scoring with the scenario's electricity tariff in place of the spec's."""
    if comfort.kpis is None or tariff is None:
        return comfort
    kpis = dataclasses.replace(comfort.kpis, tariffs={**comfort.kpis.tariffs, "Electricity": tariff})
    return dataclasses.replace(comfort, kpis=kpis)


def _is_peak(key: str) -> bool:
    return key.startswith("hvac_") and key.endswith("_peak_kw")


class Totals:
    """The KPIs' figures over the steps added so far, one chunk of steps at a time (`comfort` with the scenario's
    prices): each chunk summarized as `evaluate` summarizes an episode, its sums added, its peaks kept if higher."""

    def __init__(self, comfort):
        self.comfort = comfort
        self.steps = 0
        self.summary: dict[str, float] = {}

    def add(self, steps: pd.DataFrame) -> None:
        if steps.empty:
            return
        for key, value in summarize(steps, self.comfort).items():
            if key in SUMS:
                self.summary[key] = self.summary.get(key, 0.0) + value
            elif _is_peak(key):
                self.summary[key] = max(self.summary.get(key, value), value)
        self.steps += len(steps)


def core_kpis(steps: pd.DataFrame, comfort, area_m2: float | None, time_rat: float | None) -> dict:
    """BOPTEST's KPI payload recomputed over all of `steps` (the scored ones), `comfort` with the scenario's prices."""
    totals = Totals(comfort)
    totals.add(steps)
    return kpi_payload(totals, area_m2, time_rat)


def kpi_payload(totals: Totals, area_m2: float | None, time_rat: float | None) -> dict:
    """BOPTEST's KPI payload from the running figures (`time_rat`: the mean time ratio, None before two advances)."""
    comfort = totals.comfort
    fuels = [f.lower() for f, _ in (comfort.kpis.hvac if comfort.kpis is not None else ())]
    if not totals.steps:
        out = dict.fromkeys(CORE, 0.0) | {"idis_tot": None, "time_rat": time_rat}
        return out | {k: None for k, names in PEAKS.items() if not any(_is(f, names) for f in fuels)}
    s = dict(totals.summary)
    s |= per_area(s, area_m2)
    out = {"tdis_tot": s.get("discomfort_kh"), "idis_tot": None, "ener_tot": s.get("hvac_energy_kwh_m2"),
           "cost_tot": s.get("cost_m2"), "emis_tot": s.get("emissions_kg_m2")}  # fmt: skip
    for key, names in PEAKS.items():
        fuel = next((f for f in fuels if _is(f, names)), None)
        out[key] = s.get(f"hvac_{fuel}_peak_kw_m2") if fuel else None
    out["time_rat"] = time_rat
    return out


def _is(fuel: str, names: tuple[str, ...]) -> bool:
    return any(fuel.replace("_", "").startswith(n) for n in names)
