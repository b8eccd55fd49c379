"""What the planner's model is told besides the weather and the clock: `--mpc occupancy_input`."""

from __future__ import annotations

import numpy as np
import pytest

from parallel_eplus.learning.model_based.control.mpc import MPC
from parallel_eplus.learning.model_based.control.saved_planner import PlannerOptions
from parallel_eplus.learning.model_based.model.dataset import Transitions
from parallel_eplus.learning.model_based.settings import MPCSettings
from parallel_eplus.training.train import train

from .test_model_based import mpc_config


@pytest.mark.slow
def test_with_occupancy_input_the_model_sees_whether_the_building_is_occupied(tmp_path, no_leaks):
    """`occupancy_input`: one more exogenous input, whether the office is occupied at the step's end. In its data it
    is each step's own (the band applied or not), in its plans the calendar's for those dates, and the exported
    planner reads the calendar's too (the export's own check: served answers equal the in-process ones)."""
    from parallel_eplus.deploy.export.policy import export
    from parallel_eplus.deploy.serve.contract import Contract

    settings = MPCSettings(explore_steps=96, refit_every=96, epochs=5, candidates=64, distill=False,
                           occupancy_input=True)  # fmt: skip
    cfg = mpc_config(tmp_path, "occupied", building="office-small", workers=1, weathers=["CA"], run_days=2,
                     timesteps=288, checkpoint_every=288, mpc=settings)  # fmt: skip
    train(cfg, progress=False)
    run = tmp_path / "runs" / "occupied"
    mpc = MPC.load(run / "planner" / "planner.pt")
    plain = MPC("office-small", MPCSettings(), 0.5, 1.0, 1)
    assert mpc.layout.n_exogenous == plain.layout.n_exogenous + 1 and mpc.exogenous_names[-1] == "occupied"
    data = Transitions.load(run / "transitions.npz", mpc.layout)
    occupied, applies = data.array("x")[:, -1], data.array("applies")
    np.testing.assert_array_equal(occupied, applies)
    assert 0.1 < occupied.mean() < 0.9  # January 2, a workday: occupied by day, not at night
    export(run / "planner", tmp_path / "served", record_days=1)
    assert Contract.read(tmp_path / "served").data["fallback"]["exogenous"] == mpc.exogenous_names
    with pytest.raises(ValueError, match="occupancy_input"):  # one of the model's inputs: not an evaluation's
        PlannerOptions.parse("occupancy_input=false").apply(mpc)
