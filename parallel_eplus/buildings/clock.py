"""The clock features a policy may observe, computed from a date and time alone: a controller server (the `serve`
extra, deploy/serve/contract.py) derives them for each request without loading a building spec or EnergyPlus's files.
"""

from __future__ import annotations

import datetime as dt
import math

WEEKDAYS = ("Mon", "Tue", "Wed", "Thu", "Fri", "Sat", "Sun")  # a spec's and a tariff's day names, Monday first

# Opt-in observation features (off for the paper's reproduction): the IT load follows a fixed daily
# schedule with steps at 00:00, 06:00, 08:00 and 18:00 that the six sensors cannot anticipate. They
# describe the start of the 15 minutes the next action controls; all lie in [-1, 1].
TIME_FEATURES = ("hour_sin", "hour_cos", "weekday_sin", "weekday_cos")
# The schedule itself, as the operator knows it: the load the next step runs at, the last and the next
# step in it, and how far away they are (in days). A step's effect on the zones is sharp in time, which
# hour sine/cosine features describe only through a sharp function a small network learns slowly.
SCHEDULE_FEATURES = ("it_load", "it_load_last_change", "days_since_change", "it_load_next_change", "days_to_change")


def time_features(t: dt.datetime) -> tuple[float, ...]:
    """Hour of day and day of week as sine/cosine pairs, each in [-1, 1]."""
    hour = 2 * math.pi * (t.hour + t.minute / 60) / 24
    day = 2 * math.pi * t.weekday() / 7
    return math.sin(hour), math.cos(hour), math.sin(day), math.cos(day)


def schedule_features(t: dt.datetime, schedule: tuple[tuple[float, float], ...]) -> tuple[float, ...]:
    """`SCHEDULE_FEATURES` at time t; every day runs the same schedule, so it wraps at midnight."""
    hour = t.hour + t.minute / 60
    i = next((k for k, (until, _) in enumerate(schedule) if hour < until), len(schedule) - 1)
    start = schedule[i - 1][0] if i else 0.0
    load, before, after = schedule[i][1], schedule[i - 1][1], schedule[(i + 1) % len(schedule)][1]
    return load, load - before, (hour - start) / 24, after - load, (schedule[i][0] - hour) / 24
