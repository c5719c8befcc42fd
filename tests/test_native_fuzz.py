"""The fuzzer of the Python FMUs (tests/fmu_fuzz_driver.py: random FMI call sequences, each in
a forked child) on the native FMUs, through tests/native_fuzz_driver.py, whose injected fault
is an allocateMemory that returns NULL (fmi2Fatal, latched). Same promises: no child dies of a
signal; every status is valid; every non-OK status comes with a logged message; after
fmi2Fatal every call returns fmi2Error and freeing still frees. 500 sequences per FMU.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

SEQUENCES = int(os.environ.get("ABU_FUZZ_SEQUENCES", "500"))  # per FMU
DRIVER = Path(__file__).resolve().parent / "native_fuzz_driver.py"


@pytest.mark.parametrize("name", ("AbuBall", "SpeedController", "Staircase"))
def test_random_call_sequences_never_crash_a_native_fmu(native_fmu_dir, tmp_path, name):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(DRIVER.parent), *filter(None, [os.environ.get("PYTHONPATH")])])}
    done = subprocess.run([sys.executable, str(DRIVER), name, str(native_fmu_dir[name]),
                           str(tmp_path), "0", str(SEQUENCES)], capture_output=True, text=True,
                          timeout=900, env=env)
    assert done.returncode == 0, done.stderr[-3000:]
    result = json.loads(done.stdout.strip().splitlines()[-1])
    totals = {int(k): v for k, v in result["totals"].items()}
    problems = result["problems"]
    print(f"\nnative {name}: {SEQUENCES} random sequences: {len(problems)} problems; statuses "
          f"OK/Warning/Discard/Error/Fatal = {[totals.get(s, 0) for s in range(5)]}; "
          f"{result['fatal_runs']} sequences latched fmi2Fatal")
    assert not problems, problems[:10]
    print(f"  {result['invalid_calls']} invalid calls (NULL or too-short arrays, unknown value "
          "references, non-finite steps and times, unknown state pointers, junk states), "
          "each refused with fmi2Error or worse and a logged message")
    assert totals.get(0) and totals.get(3) and result["fatal_runs"] > 0  # all paths reached
    assert result["invalid_calls"] > SEQUENCES  # the invalid calls were made
