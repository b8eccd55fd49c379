"""The ensemble's forward as one ONNX graph, run by onnxruntime: the planner's only model call, in training,
`evaluate` and `serve` alike.

One call takes every member's inputs for a batch of candidates, `[members, batch, inputs]` in physical units
(state, last action, action, exogenous inputs: dataset.py's row), and returns every member's prediction,
`[members, batch, targets]` in physical units (each temperature's change, each energy term's next value). The
normalizers are nodes of the graph, so the file alone is the model. Why onnxruntime and not torch: one decision is
24 forwards of a few MFLOP each, where torch's per-call overhead is as large as the arithmetic (docs/speed.md);
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


class OnnxEnsemble:
    """`forward(inputs) -> targets` on one onnxruntime session, one thread (the other cores run EnergyPlus)."""

    def __init__(self, graph: bytes):
        import onnxruntime as ort

        options = ort.SessionOptions()
        options.intra_op_num_threads = options.inter_op_num_threads = 1
        options.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
        self.graph = graph
        self.session = ort.InferenceSession(graph, options, providers=["CPUExecutionProvider"])
        shape = self.session.get_inputs()[0].shape
        self.members, self.n_inputs = int(shape[0]), int(shape[2])

    def __call__(self, inputs: np.ndarray) -> np.ndarray:
        return self.session.run([OUTPUT], {INPUT: np.ascontiguousarray(inputs, np.float32)})[0]
