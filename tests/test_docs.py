"""The documentation: the site builds with `mkdocs build --strict` (a broken link, a page missing from the navigation
or an API reference that does not resolve fails), its Python example runs, and the Markdown outside docs/ links only
to files that exist."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
MKDOCS = Path(sys.executable).with_name("mkdocs")
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")


def _build(config: Path, site: Path) -> subprocess.CompletedProcess:
    assert MKDOCS.is_file(), "mkdocs is not installed: pip install -e '.[docs]' (scripts/setup.sh does)"
    env = os.environ | {"NO_MKDOCS_2_WARNING": "1"}  # Material's notice about its successor, not about our pages
    cmd = [MKDOCS, "build", "--strict", "--config-file", config, "--site-dir", site]
    return subprocess.run(cmd, cwd=config.parent, env=env, capture_output=True, text=True, timeout=300)


@pytest.mark.slow
def test_the_site_builds_strictly_with_its_api_reference(tmp_path):
    done = _build(ROOT / "mkdocs.yml", tmp_path / "site")
    assert done.returncode == 0, done.stderr[-4000:]
    api = (tmp_path / "site" / "api" / "index.html").read_text()
    for name in ("envs.env.EnergyPlusEnv", "envs.vector_env.EnergyPlusVectorEnv", "buildings.spec.load_spec",
                 "buildings.building.load_building", "training.train.train", "training.config.TrainConfig",
                 "evaluation.sweep.run_sweep"):  # fmt: skip
        assert f'id="parallel_eplus.{name}"' in api, name
    assert not list(ROOT.glob("site")), "the build wrote into the checkout"


@pytest.mark.slow
def test_a_link_out_of_docs_to_a_missing_file_fails_the_build(tmp_path):
    """Links from docs/ to the rest of the repository are checked against the checkout (tools/docs_links.py)."""
    (tmp_path / "docs").mkdir()
    (tmp_path / "present.md").write_text("# here\n")
    (tmp_path / "docs" / "index.md").write_text("# Home\n\n[there](../present.md) and [gone](../missing.md)\n")
    config = tmp_path / "mkdocs.yml"
    config.write_text(
        f"site_name: t\nhooks: [{ROOT / 'tools' / 'docs_links.py'}]\n"
        "extra:\n  source:\n    url: https://example.org/repo\n    branch: main\n"
    )
    done = _build(config, tmp_path / "site")
    assert done.returncode != 0
    assert "the link to ../missing.md names no file in the repository" in done.stderr
    assert "present.md names no file" not in done.stderr


@pytest.mark.slow
def test_the_api_pages_python_example_runs(tmp_path, monkeypatch, no_leaks):
    (snippet,) = re.findall(r"```python\n(.*?)```", (ROOT / "docs" / "api.md").read_text(), flags=re.S)
    monkeypatch.chdir(tmp_path)
    names = {"__name__": "__docs__"}
    exec(compile(snippet, "docs/api.md", "exec"), names)
    assert names["model_zip"] == tmp_path / "runs" / "py" / "model.zip" and names["model_zip"].is_file()
    assert sorted(names["table"]["controller"]) == ["Baseline", "TRPO (CA)"]


def test_markdown_outside_docs_links_to_files_that_exist():
    """README.md, CHANGELOG.md, studies/, scripts/, tools/ and results/ read on the repository's file view: every
    relative link there names a file or folder of the checkout (docs/ is the site's, checked by the build)."""
    tracked = subprocess.run(["git", "ls-files", "*.md"], cwd=ROOT, capture_output=True, text=True, check=True)
    pages = {ROOT / f for f in tracked.stdout.split() if not f.startswith("docs/")}
    pages |= {p for d in ("studies", "scripts", "tools") for p in (ROOT / d).rglob("*.md")}
    broken = []
    for page in sorted(pages):
        text = re.sub(r"```.*?```", "", page.read_text(), flags=re.S)
        for target in LINK.findall(text):
            if re.match(r"^[a-z][a-z0-9+.-]*:", target, flags=re.I) or target.startswith("#"):
                continue
            if not (page.parent / target.split("#")[0]).exists():
                broken.append(f"{page.relative_to(ROOT)}: {target}")
    assert not broken, broken


# A work log's marks: a date that is not part of an ISO timestamp (a log line's "2026-12-07 03:25:38" or a dated
# study; an API example's "2021-01-05T10:00:00" is data, so a date followed by T and a time is allowed), a machine's
# load average, and an issue number. Studies and results READMEs keep theirs; the guide links there.
WORK_LOG = re.compile(r"\b20\d{2}-\d{2}-\d{2}\b(?!T\d)|load average|\bissues? #?\d+", flags=re.I)
GUIDE_LINES, GUIDE_PAGE_LINES = 3068, 300  # half of the 6,136 lines docs/ had before the guide was rewritten


def _guide_pages() -> list[Path]:
    """docs/*.md, the generated reference (docs/reference/) apart."""
    return sorted((ROOT / "docs").glob("*.md"))


def test_the_guide_carries_no_work_log():
    """No dates, machine loads or issue numbers in the guide (ISO timestamps inside examples are data)."""
    found = [
        f"{page.relative_to(ROOT)}:{number}: {match.group(0)}"
        for page in _guide_pages()
        for number, line in enumerate(page.read_text().splitlines(), 1)
        for match in WORK_LOG.finditer(line)
    ]
    assert not found, found


def test_the_guide_stays_short():
    """No page over 300 lines, and the guide as a whole at most half of what it was: a study's details go to its
    studies/<name>/README.md or the results/ README it produced, option lists to the generated reference."""
    lengths = {page.name: len(page.read_text().splitlines()) for page in _guide_pages()}
    assert not {name: n for name, n in lengths.items() if n > GUIDE_PAGE_LINES}
    assert sum(lengths.values()) <= GUIDE_LINES, sum(lengths.values())


def test_the_readme_stays_the_short_guide():
    """The README is the short guide (under 10 KB); each section links its page in docs/."""
    readme = (ROOT / "README.md").read_text()
    assert len(readme.encode()) < 10 * 1024
    sections = re.split(r"^## ", readme, flags=re.M)[1:]
    unlinked = [section.splitlines()[0] for section in sections if "](docs/" not in section]
    assert not unlinked, unlinked
