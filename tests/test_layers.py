"""The package's layers (docs/architecture.md), as import-linter checks them: no upward import, no cycle."""

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_layers_contract_is_kept():
    lint = Path(sys.executable).with_name("lint-imports")
    done = subprocess.run([str(lint), "--no-cache"], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-2000:]
    assert "0 broken" in done.stdout


def test_every_folder_says_what_it_owns_and_may_import():
    folders = [p for p in (ROOT / "parallel_eplus").iterdir() if (p / "__init__.py").is_file() and p.name != "models"]
    for folder in folders:
        doc = (folder / "__init__.py").read_text().split('"""')
        assert len(doc) >= 3 and "import" in doc[1], f"{folder.name}/__init__.py: say what the folder may import"


def test_a_checkpoint_pickled_before_the_move_still_loads():
    """Checkpoints saved before 0.3 name `parallel_eplus.training.lagrangian` in their pickles (`--resume`): the old
    import paths are gone in 1.0, and `load_model` still reads such a file, leaving no old path importable."""
    import importlib

    from parallel_eplus.learning.algorithms import ALGORITHMS
    from parallel_eplus.learning.lagrangian import ConstrainedRolloutBuffer, Lagrangian
    from parallel_eplus.learning.saved_models import MOVED, load_model

    old = ROOT / "results/learned/datacenter-2zone/logstd-3/datacenter-2zone-seed0/model.zip"
    model = load_model(ALGORITHMS["trpo"], old, device="cpu")
    assert isinstance(model.comfort, Lagrangian)
    assert model.rollout_buffer_class is ConstrainedRolloutBuffer
    for path in MOVED:
        with pytest.raises(ModuleNotFoundError):
            importlib.import_module(path)
