"""The lint the suite runs with the pinned ruff of the `dev` extra: `ruff check` (pyproject.toml's [tool.ruff] rules)
and `ruff format --check` (`ruff format .` fixes what it finds)."""

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_ruff_check_passes():
    ruff = Path(sys.executable).with_name("ruff")
    done = subprocess.run([str(ruff), "check", "."], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stdout[-4000:] + done.stderr[-2000:]


def test_ruff_format_leaves_every_file_as_it_is():
    ruff = Path(sys.executable).with_name("ruff")
    done = subprocess.run([str(ruff), "format", "--check", "."], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, "run `ruff format .`:\n" + done.stdout[-4000:] + done.stderr[-2000:]


def test_ruff_is_the_pinned_version():
    """The `dev` extra pins ruff; a venv with another version lints by other rules."""
    import re
    import tomllib

    dev = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]["dev"]
    (pin,) = [re.fullmatch(r"ruff==(\S+)", d).group(1) for d in dev if d.startswith("ruff")]
    ruff = Path(sys.executable).with_name("ruff")
    version = subprocess.run([str(ruff), "--version"], capture_output=True, text=True, check=True).stdout.split()[1]
    assert version == pin, f"ruff {version} here, pyproject.toml pins {pin}: pip install -e '.[dev]'"
