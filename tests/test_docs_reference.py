"""The generated reference (docs/reference/*.md: the CLI, the spec's keys, the presets, the learner settings) is what
the code generates now: tools/gen_reference.py rewrites it, and a stale page fails here and in `mkdocs build
--strict` (the script is also a hook of mkdocs.yml)."""

from __future__ import annotations

import importlib.util
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _generator():
    spec = importlib.util.spec_from_file_location("gen_reference", ROOT / "tools" / "gen_reference.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_committed_reference_is_what_the_code_generates():
    stale = _generator().stale_pages()
    assert not stale, f"stale: {stale}; run .venv/bin/python tools/gen_reference.py and commit docs/reference/"


def test_every_spec_key_the_loader_reads_is_documented_and_no_other():
    assert _generator().spec_key_problems() == []


def test_a_key_a_loader_starts_reading_is_found(tmp_path):
    """The check reads the loader's source: a new `data.get("...")` or `_need(table, "...")` is a key it sees."""
    gen = _generator()
    source = textwrap.dedent("""
        def reader(data, table, errors):
            a = data.get("new_key", 1)
            b = _need(table, "needed", "where.", errors)
            c = "flag" in data
            d = set(table) - {"allowed"}
            return data["indexed"]
        """)
    names: dict = {}
    exec(compile(source, str(tmp_path / "reader.py"), "exec"), names)
    (tmp_path / "reader.py").write_text(source)
    assert gen._keys_read(names["reader"]) == {"new_key", "needed", "flag", "allowed", "indexed"}


def test_every_reference_page_is_in_the_navigation():
    nav = (ROOT / "mkdocs.yml").read_text()
    for page in _generator().PAGES:
        assert f"reference/{page}" in nav, page
    assert "tools/gen_reference.py" in nav, "mkdocs.yml's hooks should run the staleness check"
