"""EnergyPlus alone, ten 1-day periods in one process: wall and each run's seconds (for the timeline's comparison)."""

import sys
import tempfile
from pathlib import Path

from parallel_eplus.bench.short import alone_episodes

days = int(sys.argv[1]) if len(sys.argv) > 1 else 1
with tempfile.TemporaryDirectory() as tmp:
    r = alone_episodes(days, 10, "CA", Path(tmp))
print(f"wall {r['wall_s']:.3f} runs " + " ".join(f"{x * 1e3:.0f}" for x in r["runs_s"]), f"sum {sum(r['runs_s']):.3f}")
