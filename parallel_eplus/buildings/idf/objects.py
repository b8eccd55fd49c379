"""An IDF's objects, read by a small tokenizer that skips comments, so a commented-out object is never taken for one:
what the prepared copy edits (idf_prep.py) and what `building init` and the takeover read (loops.py, takeover.py)."""

from __future__ import annotations

import re
from dataclasses import dataclass
from functools import lru_cache

_TOKEN = re.compile(r"!.*|[,;]")


@dataclass(frozen=True)
class IdfObject:
    """One object: its class, its fields (stripped, comments dropped) and its span in the text."""

    kind: str
    fields: list[str]
    start: int
    end: int  # just after its ';'
    spans: list[tuple[int, int]]  # each field's text in the IDF (what `set_fields` rewrites, comments kept)


def idf_objects(text: str) -> list[IdfObject]:
    """Every object of an IDF text in order (comments skipped; fields split on commas, the object on ';').

    The last texts' objects are kept: `building init` and `check` read the same model from several places (seven
    parses of a clinic's 1.9 MB model, 0.2 s each), and an IdfObject is never changed once read."""
    return list(_parsed(text))


@lru_cache(maxsize=2)
def _parsed(text: str) -> tuple[IdfObject, ...]:
    objects: list[IdfObject] = []
    values: list[str] = []
    spans: list[tuple[int, int]] = []
    start = pos = 0
    piece, span = "", None
    for m in _TOKEN.finditer(text):
        chunk = text[pos : m.start()]
        if chunk.strip():
            first = pos + len(chunk) - len(chunk.lstrip())
            span = (first if span is None else span[0], pos + len(chunk.rstrip()))
            if not values and not piece.strip():  # the class name begins here
                start = first
        piece += chunk
        pos = m.end()
        if m.group(0).startswith("!"):
            continue
        values.append(piece.strip())
        spans.append(span or (m.start(), m.start()))
        piece, span = "", None
        if m.group(0) == ";":
            objects.append(IdfObject(values[0], values[1:], start, m.end(), spans[1:]))
            values, spans = [], []
    return tuple(objects)
