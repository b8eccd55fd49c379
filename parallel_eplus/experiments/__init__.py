"""Many runs at once: seeds and sweeps as Ray Tune trials, the run registry's views, the algorithm comparison
and the online protocol (a policy that keeps learning through each test year).

May import training, learning, evaluation and everything below; not cli or bench.
"""
