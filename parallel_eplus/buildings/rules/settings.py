"""A rule's settings as its spec gives them (`controller_settings = { request_k = 0.02 }`): the fields of the
rule's config dataclass, checked against it, so a typo fails before a run with the names it takes."""

from __future__ import annotations

from dataclasses import fields
from typing import TypeVar

from parallel_eplus.buildings.spec.sections import did_you_mean

T = TypeVar("T")


def rule_config(cls: type[T], settings: dict, rule: str) -> T:
    """`cls` (a rule's config dataclass) with the spec's `settings` over its defaults, or a ValueError that says
    which setting is wrong and which the rule takes."""
    known = {f.name: f for f in fields(cls)}  # type: ignore[arg-type]
    for key, value in settings.items():
        if key not in known:
            raise ValueError(f"controller_settings: {rule} has no setting {key!r}{did_you_mean(key, known)}; it "
                             f"takes {', '.join(known)}")  # fmt: skip
        default = known[key].default
        if isinstance(default, (int, float)) and not isinstance(default, bool) and (
                isinstance(value, bool) or not isinstance(value, (int, float))):  # fmt: skip
            raise ValueError(f"controller_settings: {rule}'s {key} is a number, not {value!r}")
    return cls(**{k: float(v) if isinstance(known[k].default, float) else v for k, v in settings.items()})
