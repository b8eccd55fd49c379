"""What a plan takes (runtime/planner.py): the planner's settings, one type for the in-process and the served planner,
and one request per decision, which refuses a field of the wrong shape by name."""

from __future__ import annotations

from dataclasses import MISSING, fields, replace

import numpy as np
import pytest

from parallel_eplus.learning.model_based.runtime.demand import DemandOutlook
from parallel_eplus.learning.model_based.runtime.planner import Planner, PlannerSettings, PlanRequest
from parallel_eplus.learning.model_based.settings import MPCSettings

W, H, A, S, X, K = 2, 4, 3, 5, 2, 2  # workers, horizon, actions, state (K temperatures, then energy), exogenous


def _request(**changes) -> PlanRequest:
    rng = np.random.default_rng(0)
    request = PlanRequest(
        state=rng.uniform(20, 24, (W, S)), last_action=np.zeros((W, A)), exogenous=np.zeros((W, H, X)),
        applies=np.ones((W, H)), bounds=np.tile([21.0, 25.0], (W, H, K, 1)), comfort_weight=10.0,
        support=(-np.ones(A), np.ones(A)), warm=np.zeros((W, H, A)), seeds=[1, 2],
    )  # fmt: skip
    return replace(request, **changes)


def _planner(horizon: int = H) -> Planner:
    def forward(x: np.ndarray) -> np.ndarray:  # [E, B, inputs] -> [E, B, S]: temperatures follow the first action
        out = np.zeros((*x.shape[:2], S), np.float32)
        out[:, :, :K] = x[:, :, S + A : S + A + 1] + np.arange(x.shape[0])[:, None, None] * 0.01
        out[:, :, K:] = 1000.0
        return out

    settings = PlannerSettings(horizon=horizon, candidates=16, iterations=2, elites=4, max_increment=0.15,
                               init_std=0.1, disagreement_weight=0.2)  # fmt: skip
    return Planner(forward, 3, K, settings, 0.5, 1e-3)


def test_a_request_refuses_a_field_of_the_wrong_shape_naming_it():
    request = _request()
    assert request.state.dtype == np.float32 and request.seeds == (1, 2) and request.horizon == H
    with pytest.raises(ValueError, match=r"PlanRequest\.warm: shape \(2, 5, 3\), expected \[W=2, H=4, A=3\]"):
        _request(warm=np.zeros((W, H + 1, A)))
    with pytest.raises(ValueError, match=r"PlanRequest\.bounds: shape \(2, 4, 2\), expected \[W=2, H=4, K, 2\]"):
        _request(bounds=np.zeros((W, H, K)))
    with pytest.raises(ValueError, match=r"PlanRequest\.last_action: shape \(3, 3\), expected \[W=2, A\]"):
        _request(last_action=np.zeros((W + 1, A)))
    with pytest.raises(ValueError, match=r"PlanRequest\.seeds: 1 seeds, expected one per worker \(W=2\)"):
        _request(seeds=[1])
    with pytest.raises(ValueError, match=r"PlanRequest\.support\[1\]: shape \(2,\), expected \[A=3\]"):
        _request(support=(-np.ones(A), np.ones(A - 1)))
    with pytest.raises(ValueError, match=r"PlanRequest\.reference: shape \(2, 4, 2\), expected \[W=2, H=4, A=3\]"):
        _request(reference=np.zeros((W, H, A - 1)))
    with pytest.raises(ValueError, match=r"PlanRequest\.hold: shape \(3,\), expected \[W=2\]"):
        _request(hold=np.zeros(W + 1))
    prices = np.zeros((W, H - 1, 2))
    with pytest.raises(ValueError, match=r"PlanRequest\.demand\.prices: shape \(2, 3, 2\), expected \[W=2, H=4, C\]"):
        _request(demand=DemandOutlook(prices, prices, 0, 1.0))


def test_the_planner_refuses_a_request_for_another_horizon_and_plans_one_for_its_own():
    with pytest.raises(ValueError, match="4 steps ahead, the planner's horizon is 6"):
        _planner(horizon=6).plan(_request())
    plan = _planner().plan(_request())
    assert plan.action.shape == (W, A) and plan.increments.shape == (W, H, A) and plan.cost.shape == (W,)
    again = _planner().plan(_request())  # seeded by the request: the same answer
    assert np.array_equal(plan.action, again.action) and np.array_equal(plan.cost, again.cost)


def test_a_contract_without_a_later_setting_plans_with_mpc_settings_default():
    """The served planner reads its settings from the contract; a field an older contract lacks takes its default,
    which must be the one the in-process planner had (MPCSettings')."""
    mpc = MPCSettings()
    required = {f.name: getattr(mpc, f.name) for f in fields(PlannerSettings) if f.default is MISSING}
    # every contract has held these; the rest came later
    assert set(required) == {"horizon", "candidates", "iterations", "elites", "max_increment", "init_std",
                             "disagreement_weight"}  # fmt: skip
    assert PlannerSettings.of(required) == PlannerSettings.of(mpc)
    assert PlannerSettings.of({**vars(mpc), "unknown": 1}) == PlannerSettings.of(mpc)  # other keys ignored


def _ensemble(members: int = 3, n_in: int = S + 2 * A + X, hidden: int = 16, seed: int = 0):
    from parallel_eplus.learning.model_based.runtime.ensemble_graph import EnsembleArrays

    rng = np.random.default_rng(seed)
    sizes = [n_in, hidden, hidden, S]
    pairs = zip(sizes[:-1], sizes[1:], strict=True)
    weights = [rng.normal(0, 0.5, (members, a, b)).astype(np.float32) for a, b in pairs]
    biases = [rng.normal(0, 0.1, (members, 1, b)).astype(np.float32) for b in sizes[1:]]
    return EnsembleArrays(weights, biases, rng.normal(0, 1, n_in), rng.uniform(0.5, 2, n_in),
                          rng.normal(0, 0.1, S), rng.uniform(0.1, 1, S))  # fmt: skip


@pytest.mark.parametrize("horizon", [1, H])
def test_the_rollout_graph_gives_the_numbers_of_a_forward_per_step_and_the_same_plans(horizon):
    """One call of the rollout graph per CEM iteration (ensemble_graph.py `build_rollout`) is the forward stepped
    over the horizon with the state carried in numpy, to the last bit: the same costs and plans, with a reference,
    energy weights, demand charges, each member's cost (`consensus`) and the worst member's comfort."""
    from parallel_eplus.learning.model_based.runtime.ensemble_graph import OnnxEnsemble, build_graph, build_rollout

    arrays = _ensemble()
    forward = OnnxEnsemble(build_graph(arrays), {(horizon, K): build_rollout(arrays, horizon, K)})
    rollout = forward.rollout(horizon, K)
    assert rollout is not None
    settings = PlannerSettings(horizon=horizon, candidates=24, iterations=2, elites=6, max_increment=0.15,
                               init_std=0.1, disagreement_weight=0.2, comfort_risk="worst", terminal_weight=1.0,
                               consensus=True, min_saving=0.01)  # fmt: skip
    graph = Planner(forward, 3, K, settings, 0.5, 1e-3)
    stepped = Planner(lambda x: forward(x), 3, K, settings, 0.5, 1e-3)  # no `rollout`: a forward per step
    rng = np.random.default_rng(3)
    request = PlanRequest(
        state=rng.uniform(20, 24, (W, S)), last_action=rng.uniform(-0.5, 0.5, (W, A)),
        exogenous=rng.normal(0, 1, (W, horizon, X)), applies=np.ones((W, horizon)),
        bounds=np.tile([21.0, 25.0], (W, horizon, K, 1)), comfort_weight=10.0, support=(-np.ones(A), np.ones(A)),
        warm=rng.normal(0, 0.05, (W, horizon, A)), seeds=[1, 2], energy_weights=rng.uniform(0.5, 2, (W, horizon, 3)),
        reference=rng.uniform(-0.5, 0.5, (W, horizon, A)), follows=np.array([True, True, False]),
        demand=DemandOutlook(rng.uniform(0, 5, (W, horizon, 2)), rng.uniform(0, 1, (W, horizon, 2)), 1, 0.1),
    )  # fmt: skip
    actions = np.clip(rng.normal(0, 0.5, (W, 7, horizon, A)), -1, 1).astype(np.float32)
    assert np.array_equal(graph._rollout(request.state, request.last_action, actions, request.exogenous),
                          stepped._rollout(request.state, request.last_action, actions, request.exogenous))  # fmt: skip
    a, b = graph.plan(request), stepped.plan(request)
    for name in ("action", "increments", "cost", "spread_k"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
