"""The benchmark itself, end to end on a tiny size: every measurement runs and the table reads it."""

from __future__ import annotations

import json

import pytest

from parallel_eplus.bench import BenchConfig, format_table, run


def test_bench_measures_everything_and_writes_json(tmp_path, no_leaks):
    cfg = BenchConfig(raw_days=1, vector_steps=40, train_steps=128, batch_size=128, workers=2, repeats=1)
    out = tmp_path / "bench.json"
    results = run(cfg, out)
    assert json.loads(out.read_text()) == results
    assert results["env_steps_per_s"] > 0 and results["env_over_raw"] == results["env_s"] / results["raw_s"]
    # Two raw runs at once take at least about as long as one (not half: each does a whole run).
    assert results["raw_scaling"] == pytest.approx(results["raw_s"] / results["raw_n_s"])
    assert 0.2 < results["raw_scaling"] < 1.5
    for n in ("1", "n"):
        assert results[f"vector_{n}_steps_per_s"] > 0
        assert 0 < results[f"vector_{n}_cores_busy"] <= cfg.workers + 0.5
    assert results["lockstep_n_steps_per_s"] > 0
    assert results["lockstep_scaling"] == pytest.approx(
        results["lockstep_n_steps_per_s"] / (2 * results["vector_1_steps_per_s"])
    )
    assert results["independent_n_steps_per_s"] > 0
    assert results["independent_scaling"] == pytest.approx(
        results["independent_n_steps_per_s"] / (2 * results["vector_1_steps_per_s"])
    )
    assert results["update_s"] > 0 and results["train_steps_per_s"] > 0
    table = format_table(results)
    assert "2 runs at once" in table and "cores busy" in table and "stepped alone" in table and "lockstep" in table
