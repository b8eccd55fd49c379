"""Policy networks learned from the planner: by imitation (`distill.py`) or through the model's gradient
(`through_model.py`).
"""
