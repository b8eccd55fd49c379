"""The ensemble's forward as one ONNX graph, run by onnxruntime: the planner's only model call, in training,
`evaluate` and `serve` alike.

One call takes every member's inputs for a batch of candidates, `[members, batch, inputs]` in physical units
(state, last action, action, exogenous inputs: dataset.py's row), and returns every member's prediction,
`[members, batch, targets]` in physical units (each temperature's change, each energy term's next value). The
normalizers are nodes of the graph, so the file alone is the model. The planner runs it as `build_rollout`'s graph:
the whole horizon in one call, the same numbers. Why onnxruntime and not torch: one decision is 24 forwards of a
few MFLOP each, where torch's per-call overhead is as large as the arithmetic (docs/speed.md);
and a served planner needs neither torch nor SB3. The same graph everywhere makes a served plan equal the
in-process one to the last bit (given the same request).

Building the graph needs `onnx` (training and export); running it needs onnxruntime alone (the server).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

OPSET = 18  # Split's num_outputs
INPUT, OUTPUT = "inputs", "targets"


@dataclass
class EnsembleArrays:
    """The stacked members as numbers: weights [members, in, out] and biases [members, 1, out] per layer
    (SiLU between them), and the normalizers of inputs and targets."""

    weights: list[np.ndarray]
    biases: list[np.ndarray]
    x_mean: np.ndarray
    x_std: np.ndarray
    y_mean: np.ndarray
    y_std: np.ndarray

    @property
    def members(self) -> int:
        return int(self.weights[0].shape[0])


def build_graph(arrays: EnsembleArrays) -> bytes:
    """The serialized ONNX model of `arrays`' forward."""
    from onnx import TensorProto, helper, numpy_helper

    inits, nodes = [], []

    def const(name: str, value: np.ndarray) -> str:
        inits.append(numpy_helper.from_array(np.asarray(value, np.float32), name))
        return name

    def op(kind: str, inputs: list[str], out: str, **attributes) -> str:
        nodes.append(helper.make_node(kind, inputs, [out], **attributes))
        return out

    x = op("Sub", [INPUT, const("x_mean", arrays.x_mean)], "centred")
    x = op("Div", [x, const("x_std", arrays.x_std)], "normalized")
    # One 2-D Gemm per member and layer, not a batched 3-D MatMul: onnxruntime prepacks a 2-D constant weight
    # once, where the batched product repacks the stacked weights every call (13 % of a forward).
    members, last = arrays.members, len(arrays.weights) - 1
    inits.append(numpy_helper.from_array(np.array([0], np.int64), "axis0"))
    nodes.append(helper.make_node("Split", [x], [f"member{e}" for e in range(members)], axis=0,
                                  num_outputs=members))  # fmt: skip
    outs = []
    for e in range(members):
        h = op("Squeeze", [f"member{e}", "axis0"], f"rows{e}")
        for i, (w, b) in enumerate(zip(arrays.weights, arrays.biases, strict=True)):
            h = op("Gemm", [h, const(f"w{i}_{e}", w[e]), const(f"b{i}_{e}", b[e, 0])], f"dense{i}_{e}")
            if i < last:  # SiLU: x * sigmoid(x)
                h = op("Mul", [h, op("Sigmoid", [h], f"sig{i}_{e}")], f"silu{i}_{e}")
        outs.append(op("Unsqueeze", [h, "axis0"], f"out{e}"))
    x = op("Concat", outs, "members", axis=0)
    x = op("Mul", [x, const("y_std", arrays.y_std)], "scaled")
    op("Add", [x, const("y_mean", arrays.y_mean)], OUTPUT)
    n_in, n_out = arrays.weights[0].shape[1], arrays.weights[-1].shape[2]
    graph = helper.make_graph(
        nodes, "parallel_eplus_ensemble",
        [helper.make_tensor_value_info(INPUT, TensorProto.FLOAT, [members, "batch", n_in])],
        [helper.make_tensor_value_info(OUTPUT, TensorProto.FLOAT, [members, "batch", n_out])], inits,
    )  # fmt: skip
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", OPSET)], producer_name="parallel-eplus")
    model.ir_version = 8  # what onnxruntime >= 1.14 reads
    return model.SerializeToString()


ROLLOUT_STATE, ROLLOUT_LAST, ROLLOUT_ACTIONS, ROLLOUT_EXOGENOUS = "state", "last_action", "actions", "exogenous"
ROLLOUT_OUTPUT = "states"


def build_rollout(arrays: EnsembleArrays, horizon: int, n_temps: int) -> bytes:
    """The serialized ONNX model of the planner's rollout (planner.py `Planner._rollout`): `horizon` steps of
    `arrays`' forward, each member following its own trajectory, in one call. In: the state [B, S] (zone
    temperatures first, `n_temps` of them, then the energy parts), the last action [B, A], the candidates' actions
    [H, B, A] and exogenous inputs [H, B, X]; out: each member's state after each step, [H, E, S, B] (its zone
    temperatures plus their predicted changes, then its predicted energy parts; the candidates last, as the
    planner's cost reads them).

    The same operations on the same float32 values as `horizon` calls of `build_graph`'s forward with the state
    carried between them in numpy, so the same numbers to the last bit, arranged for fewer and cheaper nodes: the
    rows are columns (features × candidates: each feature's normalizing, and each slice and join of a row, is then
    one contiguous run instead of a few numbers per candidate; each dense layer is Wᵀ·x, the same products summed
    in the same order), what all members share (the actions, the exogenous inputs, the first state) is normalized
    once, and each member's chain runs on its own 2-D rows."""
    from onnx import TensorProto, helper, numpy_helper

    inits, nodes, count = [], [], [0]

    def const(name: str, value, dtype=np.float32) -> str:
        inits.append(numpy_helper.from_array(np.asarray(value, dtype), name))
        return name

    def op(kind: str, inputs: list[str], **attributes) -> str:
        count[0] += 1
        out = f"{kind.lower()}{count[0]}"
        nodes.append(helper.make_node(kind, inputs, [out], **attributes))
        return out

    members, k = arrays.members, n_temps
    n_state = arrays.weights[-1].shape[2]
    for i, (w, b) in enumerate(zip(arrays.weights, arrays.biases, strict=True)):  # Wᵀ [E, out, in], b [E, out, 1]
        const(f"w{i}", np.ascontiguousarray(np.swapaxes(w, 1, 2))), const(f"b{i}", np.swapaxes(b, 1, 2))
    column = lambda v: np.asarray(v, np.float32)[:, None]  # noqa: E731
    x_mean, x_std = column(arrays.x_mean), column(arrays.x_std)
    s_mean, s_std = const("s_mean", x_mean[:n_state]), const("s_std", x_std[:n_state])
    r_mean, r_std = const("r_mean", x_mean[n_state:]), const("r_std", x_std[n_state:])
    y_mean, y_std = const("y_mean", column(arrays.y_mean)), const("y_std", column(arrays.y_std))
    axis0, axis1, zero = (const(n, [v], np.int64) for n, v in (("axis0", 0), ("axis1", 1), ("zero", 0)))
    temps_end, state_end = const("k", [k], np.int64), const("n_state", [n_state], np.int64)
    # the rest of each step's row, normalized at once for every step: its last action, its action, its exogenous
    before = op("Unsqueeze", [ROLLOUT_LAST, axis0])  # [1, B, A]
    if horizon > 1:
        earlier = op("Slice", [ROLLOUT_ACTIONS, zero, const("h_1", [horizon - 1], np.int64), axis0])
        before = op("Concat", [before, earlier], axis=0)
    rest = op("Transpose", [op("Concat", [before, ROLLOUT_ACTIONS, ROLLOUT_EXOGENOUS], axis=2)], perm=[0, 2, 1])
    rest = op("Div", [op("Sub", [rest, r_mean]), r_std])  # [H, 2A + X, B]
    start = op("Transpose", [ROLLOUT_STATE], perm=[1, 0])  # [S, B]
    first = op("Div", [op("Sub", [start, s_mean]), s_std])  # every member's first state, normalized
    members_by = const("members", [members, 1, 1], np.int64)
    state, outs = op("Expand", [start, members_by]), []  # [E, S, B]
    for t in range(horizon):
        row = op("Gather", [rest, const(f"t{t}", t, np.int64)], axis=0)  # [2A + X, B]
        if t == 0:  # [D, B], the same for every member: the first layer's product broadcasts it
            x = op("Concat", [first, row], axis=0)
        else:
            x = op("Concat", [op("Div", [op("Sub", [state, s_mean]), s_std]), op("Expand", [row, members_by])], axis=1)
        for i in range(len(arrays.weights)):  # every member's dense layer at once: Wᵀ·x + b
            x = op("Add", [op("MatMul", [f"w{i}", x]), f"b{i}"])
            if i < len(arrays.weights) - 1:  # SiLU: x * sigmoid(x)
                x = op("Mul", [x, op("Sigmoid", [x])])
        y = op("Add", [op("Mul", [x, y_std]), y_mean])  # [E, S, B]: the temperatures' changes, the energy parts
        temps = op("Add", [op("Slice", [state, zero, temps_end, axis1]), op("Slice", [y, zero, temps_end, axis1])])
        state = op("Concat", [temps, op("Slice", [y, temps_end, state_end, axis1])], axis=1)
        outs.append(op("Unsqueeze", [state, axis0]))
    nodes.append(helper.make_node("Concat", outs, [ROLLOUT_OUTPUT], axis=0))  # [H, E, S, B]
    graph = helper.make_graph(
        nodes, "parallel_eplus_rollout",
        [helper.make_tensor_value_info(ROLLOUT_STATE, TensorProto.FLOAT, ["batch", n_state]),
         helper.make_tensor_value_info(ROLLOUT_LAST, TensorProto.FLOAT, ["batch", "actions"]),
         helper.make_tensor_value_info(ROLLOUT_ACTIONS, TensorProto.FLOAT, [horizon, "batch", "actions"]),
         helper.make_tensor_value_info(ROLLOUT_EXOGENOUS, TensorProto.FLOAT, [horizon, "batch", "exogenous"])],
        [helper.make_tensor_value_info(ROLLOUT_OUTPUT, TensorProto.FLOAT, [horizon, members, n_state, "batch"])],
        inits,
    )  # fmt: skip
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", OPSET)], producer_name="parallel-eplus")
    model.ir_version = 8
    return model.SerializeToString()


def arrays_of(graph: bytes) -> EnsembleArrays | None:
    """The arrays `build_graph` made `graph` of (None: a graph of another shape); needs `onnx`."""
    from onnx import load_from_string, numpy_helper

    named = {i.name: numpy_helper.to_array(i) for i in load_from_string(graph).graph.initializer}
    members = sum(1 for name in named if name.startswith("w0_"))
    layers = sum(1 for name in named if name.endswith("_0") and name.startswith("w"))
    try:
        weights = [np.stack([named[f"w{i}_{e}"] for e in range(members)]) for i in range(layers)]
        biases = [np.stack([named[f"b{i}_{e}"] for e in range(members)])[:, None] for i in range(layers)]
        return EnsembleArrays(weights, biases, *(named[n] for n in ("x_mean", "x_std", "y_mean", "y_std")))
    except (KeyError, ValueError):
        return None


class OnnxEnsemble:
    """`forward(inputs) -> targets` on one onnxruntime session, one thread (the other cores run EnergyPlus); and
    `rollout(horizon, n_temps)`, the planner's whole horizon in one call (`build_rollout`): the graph given
    (`rollouts`: its bytes by (horizon, n_temps), as an export writes it), else made from this one when `onnx` is
    installed (training, `evaluate`), else None (a served install without `onnx`, a contract without one: the
    planner steps `forward` itself)."""

    def __init__(self, graph: bytes, rollouts: dict[tuple[int, int], bytes] | None = None):
        self.graph = graph
        self.session = _session(graph)
        shape = self.session.get_inputs()[0].shape
        self.members, self.n_inputs = int(shape[0]), int(shape[2])
        self._rollouts: dict[tuple[int, int], Rollout | None] = {key: Rollout(g) for key, g in (rollouts or {}).items()}

    def __call__(self, inputs: np.ndarray) -> np.ndarray:
        return self.session.run([OUTPUT], {INPUT: np.ascontiguousarray(inputs, np.float32)})[0]

    def rollout(self, horizon: int, n_temps: int) -> Rollout | None:
        key = (horizon, n_temps)
        if key not in self._rollouts:
            try:
                arrays = arrays_of(self.graph)
            except ImportError:  # the served install: only what the export wrote
                arrays = None
            self._rollouts[key] = None if arrays is None else Rollout(build_rollout(arrays, horizon, n_temps))
        return self._rollouts[key]


class Rollout:
    """`build_rollout`'s graph on one session: (state [B, S], last action [B, A], actions [H, B, A], exogenous
    inputs [H, B, X]) -> every member's state after each step, [H, E, S, B]."""

    def __init__(self, graph: bytes):
        self.graph = graph
        self.session = _session(graph)

    def __call__(self, state: np.ndarray, last: np.ndarray, actions: np.ndarray, exo: np.ndarray) -> np.ndarray:
        feeds = {ROLLOUT_STATE: state, ROLLOUT_LAST: last, ROLLOUT_ACTIONS: actions, ROLLOUT_EXOGENOUS: exo}
        return self.session.run([ROLLOUT_OUTPUT], {k: np.ascontiguousarray(v, np.float32) for k, v in feeds.items()})[0]


def _session(graph: bytes):
    import onnxruntime as ort

    options = ort.SessionOptions()
    options.intra_op_num_threads = options.inter_op_num_threads = 1
    options.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    return ort.InferenceSession(graph, options, providers=["CPUExecutionProvider"])
