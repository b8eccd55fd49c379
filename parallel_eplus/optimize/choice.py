"""Which controller to install, decided on the held-out weathers only: the candidate with the lowest HVAC energy (or
bill) at no more occupied discomfort than the building's own controls, and the own controls when nothing beats them
(do no harm). Every figure is read from results/<period>.csv and compared on the same periods and weathers.

The tolerances, stated in every report:
- "no more occupied discomfort": at most the own controls' occupied K·h (summed over the held-out periods and
  weathers, each the mean over the zones) plus max(0.1 K·h, 1 % of it). An EnergyPlus thermostat holds its setpoint
  to a few hundredths of a kelvin (docs/kpis.md): a planner on the own plan ends a few hundredths of a K·h away.
- "saves": at least 0.5 % lower than the own controls' (the prototypes study's threshold): a controller is worth
  installing for a saving, not for a rounding.
- every held-out episode of the own controls has its candidate's counterpart: a candidate that failed on one is not
  chosen.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from parallel_eplus.optimize.candidates import OWN

KH_ALLOWANCE = 0.1  # K·h
KH_ALLOWANCE_SHARE = 0.01  # of the own controls' occupied K·h
MIN_SAVING = 0.005  # a ratio of at most 0.995 is a saving
METRIC_NAMES = {"hvac_energy_kwh": "HVAC energy", "bill": "electricity bill", "energy_kwh": "facility energy"}


def read_results(folder: Path) -> pd.DataFrame:
    frames = [pd.read_csv(p) for p in sorted(folder.glob("*.csv"))]
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()


def discomfort_column(df: pd.DataFrame) -> str:
    """Occupied K·h where the building has thermostat bounds, else its discomfort (a fixed band counts occupied steps
    only already)."""
    if "occupied_discomfort_kh" in df and df["occupied_discomfort_kh"].notna().any():
        return "occupied_discomfort_kh"
    return "discomfort_kh"


def figures(df: pd.DataFrame, held_out: bool) -> pd.DataFrame:
    """Per candidate on the training or held-out weathers: sums over the (period, weather) pairs the own controls
    scored (peak: the highest), ratios to the own controls' on the pairs both have, and how many pairs it has."""
    part = df[df.held_out == held_out]
    if part.empty:
        return pd.DataFrame()
    kh = discomfort_column(part)
    own = part[part.candidate == OWN].set_index(["period", "weather"])
    rows = []
    for key, rows_of in part.groupby("candidate", sort=False):
        mine = rows_of.set_index(["period", "weather"])
        pairs = own.index.intersection(mine.index)
        a, b = mine.loc[pairs], own.loc[pairs]
        row = {"candidate": key, "label": rows_of.label.iloc[0], "pairs": len(pairs), "own_pairs": len(own)}
        for col, how in (("hvac_energy_kwh", "sum"), ("energy_kwh", "sum"), ("bill", "sum"), ("peak_15min_kw", "max")):
            if col in part:
                mine_v, own_v = a[col].agg(how), b[col].agg(how)
                row[col], row[f"{col}_x"] = mine_v, (mine_v / own_v if own_v else float("nan"))
        row["kh"], row["kh_own"] = a[kh].sum(), b[kh].sum()
        row["in_band_pct"], row["in_band_pct_own"] = a["in_band_pct"].mean(), b["in_band_pct"].mean()
        rows.append(row)
    return pd.DataFrame(rows)


def allowed_kh(own_kh: float) -> float:
    return own_kh + max(KH_ALLOWANCE, KH_ALLOWANCE_SHARE * own_kh)


@dataclass(frozen=True)
class Choice:
    candidate: str  # OWN: keep the own controls
    label: str
    reason: str
    verdicts: dict  # candidate -> why it was or was not chosen


def choose(held: pd.DataFrame, metric: str, weathers: list[str]) -> Choice:
    """The held-out figures' (`figures(df, True)`) choice, with a verdict per candidate."""
    name = METRIC_NAMES[metric]
    verdicts, eligible = {}, []
    for _, r in held.iterrows():
        if r.candidate == OWN:
            continue
        ratio, limit = r.get(f"{metric}_x", float("nan")), allowed_kh(r.kh_own)
        if r.pairs < r.own_pairs:
            verdicts[r.candidate] = f"scored on {r.pairs} of {r.own_pairs} held-out periods: not chosen"
        elif pd.isna(ratio):
            verdicts[r.candidate] = f"no {name} figure"
        elif r.kh > limit:
            verdicts[r.candidate] = (f"{name} ×{ratio:.3f} but {r.kh:.2f} occupied K·h, above the "
                                     f"{limit:.2f} allowed (own {r.kh_own:.2f})")  # fmt: skip
        elif ratio > 1 - MIN_SAVING:
            verdicts[r.candidate] = (f"{name} ×{ratio:.3f}: not {100 * MIN_SAVING:.1f} % lower than the own "
                                     f"controls' (at {r.kh:.2f} occupied K·h, own {r.kh_own:.2f})")  # fmt: skip
        else:
            verdicts[r.candidate] = f"{name} ×{ratio:.3f} at {r.kh:.2f} occupied K·h (own {r.kh_own:.2f}, allowed "\
                                    f"{limit:.2f})"  # fmt: skip
            eligible.append((ratio, r.candidate, r.label))
    where = ", ".join(weathers)
    if not eligible:
        why = (f"no candidate's {name} on the held-out weathers ({where}) is {100 * MIN_SAVING:.1f} % lower at no "
               "more occupied discomfort: keep your own controls")  # fmt: skip
        return Choice(OWN, "own controls", why, verdicts)
    ratio, key, label = min(eligible)
    return Choice(key, label, f"{verdicts[key]} on the held-out weathers ({where}), the lowest {name} of the "
                  "candidates that hold the own controls' comfort", verdicts)  # fmt: skip
