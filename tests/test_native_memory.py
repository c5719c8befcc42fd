"""Flat memory for the native FMUs: the cycles of tests/test_fmu_memory.py (load, instantiate,
initialise, step, get and free a state, terminate, free, unload; 1000 after 100 warm-up) in
a fresh interpreter: the resident set grows by less than 5 KB per cycle (measured: at most 0.7),
sys.path and the number of classes do not change."""
from __future__ import annotations

import json
import subprocess
import sys

from test_fmu_memory import CYCLES


def test_thousand_native_cycles_keep_memory_flat(native_fmu_dir, tmp_path):
    script = tmp_path / "cycles.py"
    script.write_text(CYCLES)
    paths = {name: str(path) for name, path in native_fmu_dir.items()}
    done = subprocess.run([sys.executable, str(script), json.dumps(paths)], capture_output=True,
                          text=True, timeout=600, cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    result = json.loads(done.stdout.strip().splitlines()[-1])
    for name, r in result.items():
        print(f"\nnative {name}: 1000 cycles after 100 warm-up: RSS {r['kb_per_cycle']:+.2f} "
              f"KB/cycle, classes {r['class_change']:+d}")
        assert r["path_same"] and r["class_change"] == 0, name
        assert r["kb_per_cycle"] < 5.0, (name, r)
