"""The FMUs in a Python host that finalises its interpreter before freeing them (issue 19.5).

libcosimpy (DNV libcosim) keeps its execution in C++ objects whose destructors run when the
Python objects holding them are collected at interpreter shutdown, i.e. after Python has been
finalised: fmi2Terminate and fmi2FreeInstance then reach the FMUs' native layer
(fmus/native/abufmu.c) with no interpreter left. Those calls have nothing left to do and must
end quietly; a correct run must not end with FMU error messages. Calls that need Python are
still refused (status and message): checked in tests/test_fmu_errors.py style by the C host.
"""
from __future__ import annotations

import subprocess
import sys

import pytest

from abu.cli.main import main

pytest.importorskip("libcosimpy")

#: The plainest script a user writes: the execution is a module global, so libcosim's
#: destructors (fmi2Terminate, fmi2FreeInstance) run during the interpreter's shutdown.
CHILD = r"""
import sys
from libcosimpy.CosimExecution import CosimExecution
from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
from libcosimpy.CosimObserver import CosimObserver

log_output_level(CosimLogLevel.WARNING)
ex = CosimExecution.from_ssp_file(sys.argv[1])
observer = CosimObserver.create_last_value()
ex.add_observer(observer)
plant = ex.slave_index_from_instance_name("plant")
vr = {v.name.decode(): v.reference for v in ex.slave_variables(plant)}
for _ in range(int(sys.argv[2])):
    assert ex.step()
print("omega", observer.last_real_values(plant, [vr["omega"]])[0], flush=True)
"""


def test_libcosimpy_run_ends_without_fmu_errors(tmp_path):
    ssp = tmp_path / "abu.ssp"
    assert main(["export-ssp", "--out", str(ssp)]) == 0
    proc = subprocess.run([sys.executable, "-c", CHILD, str(ssp), "200"], capture_output=True,
                          text=True, timeout=300)
    output = proc.stdout + proc.stderr
    print(f"\nlibcosimpy child: exit {proc.returncode}; output:\n{output.strip()}")
    assert proc.returncode == 0, output[-2000:]
    assert "omega -" in proc.stdout  # the run happened (the rotor spins at about -17 Hz)
    lowered = output.lower()
    for word in ("error", "refused", "fatal", "finalised", "traceback"):
        assert word not in lowered, output[-2000:]
