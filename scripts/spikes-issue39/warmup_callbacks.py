"""What our Python callbacks cost EnergyPlus during sizing and warm-up, before the C bridge is armed (issue 39).

Runs one 1-day data-center episode raw (no pipes, the initial action held) in this process several times and
accumulates the wall time spent inside Bridge.apply_action / Bridge.observe until the run period starts.
"""

import tempfile
import time
from pathlib import Path

from parallel_eplus.buildings.idf_prep import prepare_idf
from parallel_eplus.buildings.model import control_model
from parallel_eplus.buildings.weather import resolve_weather
from parallel_eplus.engine import bridge as br
from parallel_eplus.engine import eplus_callback, native

acc = {"calls": 0, "s": 0.0}
for name in ("apply_action", "observe"):
    f = getattr(br.Bridge, name)

    def g(self, state, _f=f):
        if self.started:
            return _f(self, state)
        t = time.perf_counter()
        _f(self, state)
        acc["s"] += time.perf_counter() - t
        acc["calls"] += 1

    setattr(br.Bridge, name, g)

model = control_model("temp_fan")
lib = native.bridge_library()
with tempfile.TemporaryDirectory() as tmp:
    idf = Path(tmp) / "model.idf"
    prepare_idf(model.idf, idf, 1, False)
    epw = resolve_weather("CA")
    init = [str(e.initial) for e in model.actions]
    for k in range(6):
        acc.update(calls=0, s=0.0)
        t = time.perf_counter()
        eplus_callback.main(["--idf", str(idf), "--epw", str(epw), "--output-dir", f"{tmp}/o{k}", "--steps", "96",
                             "--native", lib, "--initial-action", *init])  # fmt: skip
        print(
            f"run {time.perf_counter() - t:.3f} s; python callbacks before the run period: {acc['calls']} calls, "
            f"{acc['s'] * 1e3:.1f} ms"
        )
