"""The release: one version (pyproject.toml's) behind `--version`, a semantic version, its CHANGELOG section, and
the deprecation policy the CHANGELOG points to."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

import pytest

from parallel_eplus.cli import main

ROOT = Path(__file__).resolve().parents[1]
VERSION = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]


def test_version_is_semantic():
    assert re.fullmatch(r"(0|[1-9]\d*)\.(0|[1-9]\d*)\.(0|[1-9]\d*)", VERSION), VERSION


def test_the_command_prints_the_installed_version(capsys):
    with pytest.raises(SystemExit) as done:
        main(["--version"])
    assert done.value.code == 0
    assert capsys.readouterr().out.strip() == f"parallel-eplus {VERSION}"


def test_the_changelog_releases_this_version_and_links_the_deprecation_policy():
    changelog = (ROOT / "CHANGELOG.md").read_text()
    first = re.search(r"^## (\S+) \((\d{4}-\d{2}-\d{2})\)$", changelog, flags=re.M)
    assert first is not None and first.group(1) == VERSION, "the newest section is this version's, with its date"
    assert "](docs/contributing.md#versions-and-deprecation)" in changelog
    assert "## Versions and deprecation" in (ROOT / "docs" / "contributing.md").read_text()
