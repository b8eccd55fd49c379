"""What the planner's energy term counts under the run's objective: a weight per predicted energy part and step.

The model predicts the energy in parts (dataset.py's `Layout`: the non-HVAC rest and each observed HVAC signal,
or the spec's energy terms where it has no HVAC parts). The reward's energy signal (buildings/scoring/kpis.py) is, per
objective: every part (`energy`); the HVAC parts (`hvac`); each HVAC part times its fuel's price when the step
begins over electricity's mean price (`cost`); or times its fuel's emission factor over electricity's
(`emissions`). The planner weighs its predicted parts the same way at each step of its horizon, so under a
time-of-use tariff it sees the coming peak price and can move cooling ahead of it. Demand charges are priced apart,
against each month's running peak (demand.py).

Where the model has no HVAC parts (an HVAC meter the agent does not observe), `cost` prices every energy term at
electricity's price and `hvac` and `emissions` count them all: the closest the predicted terms allow.

Numpy only (and tariff.py's): the served planner builds its weights here from the contract's tariff.
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from parallel_eplus.buildings.pricing.tariff import Tariff

OBJECTIVES = ("energy", "hvac", "cost", "emissions")


@dataclass(frozen=True)
class EnergyWeights:
    """`at(starts)`: [H, P] weights of the model's P energy parts for steps beginning at `starts`."""

    objective: str
    fixed: np.ndarray  # [P]: the weights where they do not vary with time; under `cost`, which parts are priced
    fuels: tuple[str | None, ...] = ()  # under `cost`: each part's fuel (None: unpriced)
    tariffs: dict[str, Tariff] = field(default_factory=dict)
    reference_price: float = 1.0

    def at(self, starts: list[dt.datetime]) -> np.ndarray:
        if self.objective != "cost":
            return np.broadcast_to(self.fixed, (len(starts), len(self.fixed))).astype(np.float32)
        prices = {f: self.tariffs[f].series(starts) for f in set(self.fuels) - {None}}
        columns = [prices[f] / self.reference_price if f else np.zeros(len(starts)) for f in self.fuels]
        return np.stack(columns, axis=1).astype(np.float32)

    @classmethod
    def of(cls, layout, objective: str, hvac_fuels: dict[str, str], tariffs: dict[str, Tariff],
           factors: dict[str, float]) -> EnergyWeights:  # fmt: skip
        """For `layout`'s energy parts under `objective`; `hvac_fuels`: each HVAC signal's fuel (the spec's
        `[kpis] hvac`), `tariffs` and emission `factors` by fuel (kpis.py's `Kpis`)."""
        if objective not in OBJECTIVES:
            raise ValueError(f"objective {objective!r} is not one of {list(OBJECTIVES)}")
        parts = layout.state_names[len(layout.temperatures) :]
        if objective == "energy" or not hvac_fuels:
            return cls("energy", np.ones(len(parts), np.float32))
        reference = tariffs.get("Electricity")
        ref_price = (reference.mean_price() if reference is not None else 1.0) or 1.0
        if not layout.hvac:  # no HVAC parts: every term, at electricity's price under cost
            if objective != "cost" or reference is None:
                return cls("energy", np.ones(len(parts), np.float32))
            fuels = ("Electricity",) * len(parts)
            return cls("cost", np.ones(len(parts), np.float32), fuels, {"Electricity": reference}, ref_price)
        fuels = tuple(hvac_fuels.get(p) for p in parts)  # the non-HVAC rest has none
        if objective == "hvac":
            return cls("hvac", np.array([f is not None for f in fuels], np.float32))
        if objective == "emissions":
            ref = factors.get("Electricity") or 1.0
            return cls("emissions", np.array([factors.get(f, 0.0) / ref if f else 0.0 for f in fuels], np.float32))
        priced = {f: tariffs[f] for f in fuels if f is not None}
        return cls("cost", np.array([f is not None for f in fuels], np.float32), fuels, priced, ref_price)

    @classmethod
    def of_building(cls, layout, building, objective: str | None = None) -> EnergyWeights:
        """For a Building under `objective` (None: its spec's reward objective)."""
        kpis = building.comfort.kpis
        objective = objective or building.comfort.objective
        if kpis is None:
            return cls.of(layout, "energy", {}, {}, {})
        return cls.of(layout, objective, {c: f for f, c in kpis.hvac}, kpis.tariffs, kpis.factors)

    def entry(self, tariff_values: dict[str, object]) -> dict:
        """The contract's record of these weights (an exported planner's), with each priced fuel's tariff as the
        spec gives it (`tariff_values`: fuel -> a price or a table, a CSV's `csv` beside the contract)."""
        entry: dict = {"objective": self.objective, "fixed": self.fixed.tolist()}
        if self.objective == "cost":
            entry |= {"fuels": list(self.fuels), "reference_price": self.reference_price,
                      "tariffs": {f: tariff_values[f] for f in self.tariffs}}  # fmt: skip
        return entry

    @classmethod
    def from_entry(cls, entry: dict | None, parts: int, directory: Path) -> EnergyWeights:
        """From a contract's record (None: a planner exported before objectives, which counted energy)."""
        if entry is None:
            return cls("energy", np.ones(parts, np.float32))
        tariffs = {f: Tariff.of(v, Path(directory)) for f, v in entry.get("tariffs", {}).items()}
        return cls(entry["objective"], np.asarray(entry["fixed"], np.float32), tuple(entry.get("fuels", ())),
                   tariffs, float(entry.get("reference_price", 1.0)))  # fmt: skip
