"""A reused instance (fmi2Reset) that fails to initialise never crashes its host, recovers, and
runs again as before; also through the master's pool after another co-simulation was freed.

The driver (tests/fmu_reuse_driver.py) runs in a child process: a segfault fails this test
instead of killing pytest.
"""
from __future__ import annotations

import json
import signal
import subprocess
import sys
from pathlib import Path

DRIVER = Path(__file__).with_name("fmu_reuse_driver.py")
ROUNDS = 40


def test_reset_failing_init_reset_good_run_never_crashes(fmu_dir):
    folder = fmu_dir["AbuBall"].parent
    done = subprocess.run([sys.executable, str(DRIVER), str(folder), str(ROUNDS)],
                          capture_output=True, text=True, timeout=600)
    if done.returncode < 0:
        raise AssertionError(f"the host died of {signal.Signals(-done.returncode).name}:\n"
                             f"{done.stderr[-3000:]}")
    assert done.returncode == 0, done.stderr[-3000:]
    report = json.loads(done.stdout.strip().splitlines()[-1])
    assert report["direct"] == {"AbuBall": ROUNDS, "SpeedController": ROUNDS, "Staircase": ROUNDS}
    assert "'mu'" in report["pooled"]
    print(f"\n[fmu reuse] {ROUNDS} rounds of reset + failing init (x2) + recovery + reset + good "
          f"run on each of the 3 FMUs, and a failing parameter on a pooled co-simulation after "
          f"a freed one: no crash, every failure fmi2Error with a message")
