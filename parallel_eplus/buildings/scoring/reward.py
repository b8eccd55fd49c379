"""The paper's reward (Section 4.2.3): a comfort bonus per zone, a band penalty, and a power cost.

r = sum_z exp(-l1 (T_z - T_C)^2) - l2 sum_z ([T_z - T_U]+ + [T_L - T_z]+) - l_P P_total

The paper prints a minus before the Gaussian term; its authors confirmed that is a typo: the Gaussian is a
bonus of up to 1 per zone.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from parallel_eplus.buildings.spec.records import BuildingSpec


@dataclass(frozen=True)
class RewardConfig:
    """Reward constants; the defaults are the paper's. Override with a dict, JSON file or CLI flags."""

    center_c: float = 23.5  # T_C
    lower_c: float = 23.0  # T_L
    upper_c: float = 24.0  # T_U
    gaussian_weight: float = 0.5  # lambda_1
    band_weight: float = 0.1  # lambda_2
    power_weight: float = 1e-5  # lambda_P, per W

    def __post_init__(self):
        bad = {k: v for k, v in asdict(self).items() if not math.isfinite(v)}
        if bad:
            raise ValueError(f"reward constants must be finite numbers: {bad}")

    @classmethod
    def from_any(cls, value: RewardConfig | Mapping[str, Any] | str | Path | None) -> RewardConfig:
        """Accept a RewardConfig, a mapping of overrides, or a path to a JSON file of overrides."""
        if value is None:
            return cls()
        if isinstance(value, RewardConfig):
            return value
        if isinstance(value, (str, Path)):
            try:
                value = json.loads(Path(value).read_text())
            except json.JSONDecodeError as e:
                raise ValueError(f"reward file {value}: not JSON ({e})") from None
            if not isinstance(value, dict):
                raise ValueError('a reward file holds a JSON object of constants, e.g. {"power_weight": 2e-5}')
        known = {f.name for f in fields(cls)}
        unknown = set(value) - known
        if unknown:
            raise ValueError(f"unknown reward constant(s) {sorted(unknown)}; known: {sorted(known)}")
        return cls(**{k: float(v) for k, v in value.items()})

    def to_dict(self) -> dict[str, float]:
        return asdict(self)


def reward(
    zone_temps_c: tuple[float, ...], power_w: float, cfg: RewardConfig, applies: bool = True
) -> tuple[float, dict[str, float]]:
    """Reward and its components (they sum to it), as they appear in `info` and the episode records.

    `power_w`: the building's energy signal (every fuel its spec meters). Where the comfort band does not apply
    (`applies` False: an unoccupied office) the step pays for energy only."""
    comfort = 0.0
    band = 0.0
    for t in zone_temps_c if applies else ():
        comfort += math.exp(-cfg.gaussian_weight * (t - cfg.center_c) ** 2)
        above, below = t - cfg.upper_c, cfg.lower_c - t
        # max(x, 0.0) without the call (it runs every step): the same value, NaN and -0.0 included
        band += (0.0 if above < 0.0 else above) + (0.0 if below < 0.0 else below)
    parts = {
        "reward_comfort": comfort,
        "reward_band": -cfg.band_weight * band,
        "reward_power": -cfg.power_weight * power_w,
    }
    return comfort + parts["reward_band"] + parts["reward_power"], parts


def reward_config(spec: BuildingSpec) -> RewardConfig:
    """The spec's reward parameters as today's RewardConfig (center/lower/upper are in C there)."""
    suffix = {"center": "center_c", "lower": "lower_c", "upper": "upper_c"}
    return RewardConfig(**{suffix.get(k, k): v for k, v in spec.reward.params.items()})
