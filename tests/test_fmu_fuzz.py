"""Random FMI call sequences against each FMU, each in a forked child: the host never crashes.

The sequences, the family and the checks are in ``tests/fmu_fuzz_driver.py``, which this test
runs in a fresh interpreter holding only fmpy and the FMU (forking the test process itself,
with everything the suite has imported, costs several times more). Asserted: no child dies of
a signal or exits abnormally; every status is a valid fmi2Status; every non-OK status comes
with a logged message; every invalid call (NULL and too-short arrays among them) is refused
with fmi2Error or worse and a message; after fmi2Fatal every call returns fmi2Error and freeing still frees.
``pytest -s`` prints the status counts.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

SEQUENCES = int(os.environ.get("ABU_FUZZ_SEQUENCES", "500"))  # per FMU
NAMES = ("AbuBall", "SpeedController", "Staircase")
DRIVER = Path(__file__).resolve().parent / "fmu_fuzz_driver.py"


@pytest.mark.parametrize("name", NAMES)
def test_random_call_sequences_never_crash_the_host(fmu_dir, tmp_path, name):
    done = subprocess.run([sys.executable, str(DRIVER), name, str(fmu_dir[name]), str(tmp_path),
                           "0", str(SEQUENCES)], capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-3000:]
    result = json.loads(done.stdout.strip().splitlines()[-1])
    totals = {int(k): v for k, v in result["totals"].items()}
    problems = result["problems"]
    print(f"\n{name}: {SEQUENCES} random sequences of 5-40 FMI calls, each in a forked child: "
          f"{len(problems)} problems; statuses OK/Warning/Discard/Error/Fatal = "
          f"{[totals.get(s, 0) for s in range(5)]}; {result['fatal_runs']} sequences latched "
          "fmi2Fatal")
    assert not problems, problems[:10]
    print(f"  {result['invalid_calls']} invalid calls (NULL or too-short arrays, unknown value "
          "references, non-finite steps and times, unknown state pointers, junk states), "
          "each refused with fmi2Error or worse and a logged message")
    assert totals.get(0) and totals.get(3) and result["fatal_runs"] > 0  # all paths reached
    assert result["invalid_calls"] > SEQUENCES  # the invalid calls were made
