"""Ten consecutive 1-day episodes in one env (prepared), for farm-bench pairs between two trees' venvs.

farm-bench -n 6 -- .venv/bin/python scripts/spikes-issue39/ten.py \
    --vs '/other/tree/.venv/bin/python scripts/spikes-issue39/ten.py'
"""

import sys
import tempfile
import time
from pathlib import Path

import parallel_eplus
from parallel_eplus.bench.short import env_episodes

days = int(sys.argv[1]) if len(sys.argv) > 1 else 1
with tempfile.TemporaryDirectory() as tmp:
    r = env_episodes(days, 10, "CA", True, Path(tmp))
resets = " ".join(f"{x * 1e3:.0f}" for x in r["resets_s"])
print(parallel_eplus.__file__, f"wall {r['wall_s']:.3f}", resets, time.time())
