"""Eight 1-day raw episodes (our EnergyPlus side, C bridge, no pipes) in one process: the median episode seconds.
For farm-bench pairs between two trees (the warm-up held in C or in Python callbacks)."""

import statistics
import tempfile
import time
from pathlib import Path

from parallel_eplus.buildings.idf_prep import prepare_idf
from parallel_eplus.buildings.model import control_model
from parallel_eplus.buildings.weather import resolve_weather
from parallel_eplus.engine import eplus_callback, native

model = control_model("temp_fan")
lib = native.bridge_library()
took = []
with tempfile.TemporaryDirectory() as tmp:
    idf = Path(tmp) / "model.idf"
    prepare_idf(model.idf, idf, 1, False)
    init = [str(e.initial) for e in model.actions]
    for k in range(9):
        t = time.perf_counter()
        eplus_callback.main(["--idf", str(idf), "--epw", str(resolve_weather("CA")), "--output-dir", f"{tmp}/o{k}",
                             "--steps", "96", "--native", lib, "--initial-action", *init])  # fmt: skip
        took.append(time.perf_counter() - t)
print(f"median {statistics.median(took[1:]) * 1e3:.1f} ms", " ".join(f"{x * 1e3:.0f}" for x in took))
