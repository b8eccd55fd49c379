"""A deterministic policy as an ONNX graph, built from plain arrays with `onnx.helper`: no torch in the file.

Why not `torch.onnx.export`: its default exporter needs onnxscript and changes with each torch release, and the
policy is a handful of dense layers. Building them here keeps every step the in-process policy takes, in its
order and precision (float64, with the casts to float32 where `evaluate` makes them), so onnxruntime gives the
same setpoints to the last bits: sensor clipping to the spec's bounds, VecNormalize's scaling and clip, the MLP,
the action clip (or SAC's tanh squash), the scaling to each actuator's physical range, and a zone's heating
setpoint kept at or below its cooling one.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

OPSET = 17
INPUT = "observation"  # float32 [batch, observations], in the contract's input order
OUTPUT = "setpoints"  # float64 [batch, actions], physical units, in the contract's output order


@dataclass
class Layer:
    """One step of the network: a dense layer (weight [in, out], bias) or an activation."""

    op: str  # "dense", "tanh", "relu", "elu", "hardtanh"
    weight: np.ndarray | None = None
    bias: np.ndarray | None = None
    params: dict[str, float] = field(default_factory=dict)  # elu's alpha; hardtanh's min and max


@dataclass
class PolicyArrays:
    """Everything between sensor readings and setpoints, as numbers."""

    obs_low: np.ndarray  # the spec's sensor bounds (features: -1, 1): the env clips readings to them
    obs_high: np.ndarray
    obs_mean: np.ndarray | None  # VecNormalize's statistics; None: observations are not normalized
    obs_std: np.ndarray | None  # sqrt(var + epsilon), as VecNormalize computes it
    clip_obs: float
    layers: list[Layer]
    squash: bool  # SAC: tanh on the network's mean; TRPO/PPO: a clip to [-1, 1]
    act_low: np.ndarray  # each action element's physical range
    act_high: np.ndarray
    pairs: tuple[tuple[int, int], ...] = ()  # (heating, cooling) outputs: heating kept at or below (model.py)


def _rounds(pairs: tuple[tuple[int, int], ...]) -> list[list[tuple[int, int]]]:
    """The pairs in rounds where each heating output appears once (one Gather each)."""
    rounds: list[list[tuple[int, int]]] = []
    for h, c in pairs:
        free = next((r for r in rounds if all(h != g for g, _ in r)), None)
        if free is None:
            rounds.append(free := [])
        free.append((h, c))
    return rounds


class _Builder:
    def __init__(self):
        self.nodes: list = []
        self.inits: list = []
        self.n = 0

    def const(self, name: str, value) -> str:
        self.inits.append(numpy_helper.from_array(np.asarray(value, dtype=np.float64), name))
        return name

    def op(self, op_type: str, inputs: list[str], out: str | None = None, **attrs) -> str:
        self.n += 1
        out = out or f"{op_type.lower()}_{self.n}"
        self.nodes.append(helper.make_node(op_type, inputs, [out], name=f"{op_type}_{self.n}", **attrs))
        return out

    def float32_round(self, x: str) -> str:
        """The float32 the in-process path holds at this point, back in float64."""
        return self.op("Cast", [self.op("Cast", [x], to=TensorProto.FLOAT)], to=TensorProto.DOUBLE)


def build_model(p: PolicyArrays, doc: str = "") -> onnx.ModelProto:
    """The ONNX model: `observation` (float32) -> `setpoints` (float64, physical units)."""
    b = _Builder()
    x = b.op("Cast", [INPUT], to=TensorProto.DOUBLE)
    x = b.op("Max", [b.op("Min", [x, b.const("obs_high", p.obs_high)]), b.const("obs_low", p.obs_low)])
    if p.obs_mean is not None:
        z = b.op("Div", [b.op("Sub", [x, b.const("obs_mean", p.obs_mean)]), b.const("obs_std", p.obs_std)])
        z = b.op("Max", [b.op("Min", [z, b.const("clip_hi", p.clip_obs)]), b.const("clip_lo", -p.clip_obs)])
        x = b.float32_round(z)  # normalize_obs returns float32
    else:
        x = b.float32_round(x)
    for i, layer in enumerate(p.layers):
        if layer.op == "dense":
            w, bias = b.const(f"w{i}", layer.weight), b.const(f"b{i}", layer.bias)
            x = b.op("Add", [b.op("MatMul", [x, w]), bias])
        elif layer.op == "tanh":
            x = b.op("Tanh", [x])
        elif layer.op == "relu":
            x = b.op("Relu", [x])
        elif layer.op == "elu":
            x = b.op("Elu", [x], alpha=float(layer.params.get("alpha", 1.0)))
        elif layer.op == "hardtanh":
            lo, hi = b.const(f"ht_lo{i}", layer.params["min"]), b.const(f"ht_hi{i}", layer.params["max"])
            x = b.op("Max", [b.op("Min", [x, hi]), lo])
        else:
            raise ValueError(f"layer {layer.op!r} has no ONNX form here")
    one = b.const("one", 1.0)
    if p.squash:  # SAC: tanh, then onto the [-1, 1] action space as SB3's predict does: -1 + 0.5 * (a + 1) * 2
        x = b.op("Mul", [b.op("Mul", [b.const("half_", 0.5), b.op("Add", [b.op("Tanh", [x]), one])]),
                         b.const("two", 2.0)])  # fmt: skip
        x = b.op("Add", [b.const("minus_one_", -1.0), x])
    x = b.op("Max", [b.op("Min", [x, one]), b.const("minus_one", -1.0)])  # the action space; then check_action's
    x = b.float32_round(x)  # the policy's action is float32
    # scale_action (buildings/scaling.py `denormalize`): lo + (v + 1) * 0.5 * (hi - lo), in that order (* 0.5 is / 2)
    span = b.const("act_span", p.act_high - p.act_low)
    half = b.op("Mul", [b.op("Add", [x, one]), b.const("half", 0.5)])
    x = b.op("Add", [b.const("act_low", p.act_low), b.op("Mul", [half, span])])
    for i, pairs in enumerate(_rounds(p.pairs)):  # uncrossed: heating = min(heating, its cooling), as the env does
        index = np.arange(len(p.act_low))
        for h, c in pairs:
            index[h] = c
        index_name = f"paired{i}"
        b.inits.append(numpy_helper.from_array(index.astype(np.int64), index_name))
        x = b.op("Min", [x, b.op("Gather", [x, index_name], axis=1)])
    b.op("Identity", [x], out=OUTPUT)
    n_obs, n_act = len(p.obs_low), len(p.act_low)
    graph = helper.make_graph(
        b.nodes,
        "parallel_eplus_controller",
        [helper.make_tensor_value_info(INPUT, TensorProto.FLOAT, ["batch", n_obs])],
        [helper.make_tensor_value_info(OUTPUT, TensorProto.DOUBLE, ["batch", n_act])],
        b.inits,
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", OPSET)], producer_name="parallel-eplus")
    model.doc_string = doc
    onnx.checker.check_model(model, full_check=True)
    return model
