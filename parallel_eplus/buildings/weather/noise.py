"""Weather that varies per episode: Ornstein-Uhlenbeck noise on an EPW's columns, as Sinergym adds it.

Per record, `n[i+1] = n[i] - (n[i] - mu) / tau * dt + sigma * sqrt(2 / tau) * sqrt(dt) * N(0, 1)` with dt in
hours (1 for hourly files): a stationary process of mean mu, standard deviation sigma and correlation time tau
hours (its autocorrelation at lag k hours is exp(-k / tau)). The first value is drawn from that stationary law,
so every hour of the year is perturbed alike. sigma, mu and tau are given per column, each fixed or a range
`low..high` drawn per episode. Perturbed values are clipped to physical limits (`LIMITS`); where the dry bulb
or the relative humidity change, the dew point (which EnergyPlus reads for the air's moisture) follows.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from parallel_eplus.buildings.weather.epw import read_epw, records_per_hour, replace_columns

# Columns that can be perturbed: those EnergyPlus reads among the temperature, humidity and solar ones
# (global horizontal radiation is only reported: EnergyPlus uses the direct normal and diffuse parts).
LIMITS = {"drybulb": (-70.0, 70.0), "relhum": (0.0, 100.0), "dirnorrad": (0.0, 1400.0), "difhorrad": (0.0, 800.0)}
SOLAR = ("dirnorrad", "difhorrad")  # perturbed in daylight only (where the file's value is above zero)
DEFAULT_TEXT = "drybulb=1:0:24"  # Sinergym's default: dry bulb, sigma 1 K, mu 0, tau 24 h

Range = tuple[float, float]


@dataclass(frozen=True)
class OUParams:
    """One column's process: sigma (the column's unit), mu (its unit) and tau (hours), each fixed or a range."""

    sigma: Range
    mu: Range = (0.0, 0.0)
    tau_h: Range = (24.0, 24.0)

    def draw(self, rng: np.random.Generator) -> tuple[float, float, float]:
        """This episode's (sigma, mu, tau): a range is drawn uniformly, a fixed value is itself."""
        return tuple(float(lo if lo == hi else rng.uniform(lo, hi)) for lo, hi in (self.sigma, self.mu, self.tau_h))


@dataclass(frozen=True)
class WeatherNoise:
    """Which columns are perturbed and how; `parse_noise` reads the command line's form."""

    columns: dict[str, OUParams] = field(default_factory=lambda: {"drybulb": OUParams((1.0, 1.0))})


def _value(text: str, where: str) -> Range:
    lo, sep, hi = text.partition("..")
    try:
        pair = (float(lo), float(hi if sep else lo))
    except ValueError:
        raise ValueError(f"--weather-noise {where}: {text!r} is not a number or a range LOW..HIGH") from None
    if pair[0] > pair[1]:
        raise ValueError(f"--weather-noise {where}: range {text!r} runs downwards")
    return pair


def parse_noise(text: str | None) -> WeatherNoise | None:
    """'drybulb=1:0:24,relhum=2..5:0:12' -> WeatherNoise: per column SIGMA[:MU[:TAU_H]], each a number or
    LOW..HIGH (drawn per episode). None or '' -> None (no noise); 'default' -> dry bulb 1:0:24."""
    if text is None or not text.strip():
        return None
    if text.strip().lower() in ("default", "on"):
        text = DEFAULT_TEXT
    columns = {}
    for item in (p.strip() for p in text.split(",") if p.strip()):
        name, sep, values = item.partition("=")
        name = name.strip()
        if name not in LIMITS:
            raise ValueError(f"--weather-noise: column {name!r} cannot be perturbed; use {', '.join(LIMITS)}")
        parts = values.split(":") if sep else []
        if not 1 <= len(parts) <= 3:
            raise ValueError(f"--weather-noise {name}: give {name}=SIGMA[:MU[:TAU_HOURS]], e.g. {name}=1:0:24")
        sigma = _value(parts[0], f"{name} sigma")
        mu = _value(parts[1], f"{name} mu") if len(parts) > 1 else (0.0, 0.0)
        tau = _value(parts[2], f"{name} tau") if len(parts) > 2 else (24.0, 24.0)
        if sigma[0] < 0 or tau[0] <= 0:
            raise ValueError(f"--weather-noise {name}: sigma must be >= 0 and tau > 0 hours")
        columns[name] = OUParams(sigma, mu, tau)
    return WeatherNoise(columns)


def ou_noise(n: int, sigma: float, mu: float, tau_h: float, rng: np.random.Generator, dt_h: float = 1.0) -> np.ndarray:
    """n values of the Ornstein-Uhlenbeck process (module docstring), starting from its stationary law."""
    a = 1.0 - dt_h / tau_h
    eps = rng.standard_normal(n)
    drive = mu * dt_h / tau_h + sigma * math.sqrt(2.0 / tau_h) * math.sqrt(dt_h) * eps
    drive[0] = mu + sigma * eps[0]  # x[0]: the stationary law; then x[i] = a x[i-1] + drive[i]
    from scipy.signal import lfilter  # here: scipy costs every process importing the env ~1 s of start-up

    return lfilter([1.0], [1.0, -a], drive)


def dew_point(drybulb_c: np.ndarray, relhum_pct: np.ndarray) -> np.ndarray:
    """The dew point (C) of air at this dry bulb and relative humidity (Magnus formula, ASHRAE's coefficients
    within 0.4 K from -40 to 50 C)."""
    b, c = 17.62, 243.12
    gamma = np.log(np.clip(relhum_pct, 1.0, 100.0) / 100.0) + b * drybulb_c / (c + drybulb_c)
    return c * gamma / (b - gamma)


def perturb_epw(source: Path, target: Path, noise: WeatherNoise, seed: int) -> dict[str, float]:
    """Write `source` with noise on `noise.columns` to `target`; returns the drawn parameters
    (`noise_<column>_sigma`, `_mu`, `_tau_h`) for the episode's records. Same seed, same file."""
    rng = np.random.default_rng(seed)
    header, data = read_epw(source)
    dt_h = 1.0 / records_per_hour(header)
    params: dict[str, float] = {}
    values: dict[str, np.ndarray] = {}
    for name, ou in noise.columns.items():
        sigma, mu, tau = ou.draw(rng)
        params |= {f"noise_{name}_sigma": sigma, f"noise_{name}_mu": mu, f"noise_{name}_tau_h": tau}
        original = data[name].to_numpy(float)
        x = original + ou_noise(len(original), sigma, mu, tau, rng, dt_h)
        if name in SOLAR:
            x = np.where(original > 0, x, original)
        values[name] = np.clip(x, *LIMITS[name])
    if "drybulb" in values or "relhum" in values:
        drybulb = values.get("drybulb", data["drybulb"].to_numpy(float))
        dew = data["dewpoint"].to_numpy(float)
        if "relhum" in values:  # EnergyPlus takes the air's moisture from the dew point: keep them consistent
            dew = dew_point(drybulb, values["relhum"])
        values["dewpoint"] = np.minimum(dew, drybulb)  # never above the dry bulb
    replace_columns(source, target, values)
    return params
