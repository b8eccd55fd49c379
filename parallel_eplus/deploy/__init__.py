"""A trained policy outside the training stack: export it as an ONNX graph with its contract (export.py, graph.py,
contract.py) and serve it over HTTP (server.py: FastAPI, onnxruntime, no torch) or BACnet (bacnet*.py), both
running what runtime.py loads.

Beside experiments and bench: may import runs, engine, buildings, io and errors; server.py, runtime.py and contract.py
import only what the server process needs (never torch or Stable-Baselines3).
"""
