"""The planner as `serve` runs it, numpy and onnxruntime only (import-linter forbids torch here): the cross-entropy
planner (`planner.py`), the ensemble's ONNX forward (`ensemble_graph.py`), the state layout (`layout.py`), the
exogenous features (`features.py`), comfort's calendar (`calendar.py`), energy weights and demand charges
(`energy_weights.py`, `demand.py`) and the realised guard (`guard.py`).
"""
