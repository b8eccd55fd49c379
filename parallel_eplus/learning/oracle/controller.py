"""`evaluate --oracle`: the oracle as one column of the evaluation's table."""

from __future__ import annotations

import functools

from parallel_eplus.evaluation.controllers import ORACLE_KIND, Controller
from parallel_eplus.learning.oracle.search import OracleActor
from parallel_eplus.learning.oracle.settings import OracleSettings

ORACLE_LABEL = "Oracle"


def oracle_controller(options: str | None = None, label: str = ORACLE_LABEL) -> Controller:
    """The oracle with `options` (`OracleSettings`' NAME=VALUE,...), refused here if malformed."""
    settings = OracleSettings.from_text(options or "")
    return Controller(label, ORACLE_KIND, factory=functools.partial(OracleActor, settings))
