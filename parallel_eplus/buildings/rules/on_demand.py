"""The outdoor air on demand alone: the building's own controls in the controller's copy of its model, which takes
its outdoor air on demand (`ventilation = "demand"`, buildings/idf/ventilation.py). What a learned controller on a
packaged-unit building must beat is that measure, not the model's fixed minimum of outdoor air."""

from __future__ import annotations

from pathlib import Path

import numpy as np


class OnDemand:
    """Callable (observation, info) -> every action released (NaN): the building's own controls in the controller's
    copy, so `evaluate --rbc parallel_eplus.buildings.rules.on_demand:OnDemand` scores the outdoor air on demand alone,
    against `--baseline` (the model as it is)."""

    relinquishes = True  # its NaN elements mean "the building's own control" (the evaluation sets relinquish)

    def __init__(self, building: str | Path | None = None, target_c=None, **settings):
        from parallel_eplus.buildings.building import load_building

        if settings:
            raise ValueError(f"controller_settings: OnDemand takes none (given {', '.join(settings)})")

        b = load_building(building)
        if not b.spec.demand_ventilation:
            raise ValueError(f'{b.spec.name}: OnDemand scores the outdoor air on demand; set ventilation = "demand" '
                             "in the spec (docs/buildings.md)")  # fmt: skip
        self.n = len(b.actions)

    def __call__(self, obs, info: dict) -> np.ndarray:
        return np.full(self.n, np.nan, dtype=np.float32)
