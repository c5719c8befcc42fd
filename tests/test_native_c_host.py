"""The native FMUs in C hosts that have no Python at all.

* ``tests/fmu_c_host.c`` (a bare dlopen host) runs each native binary 100 steps and makes the
  same host mistakes as for the Python FMUs (tests/test_fmu_native.py): same statuses, one
  logged message per refused call, a second free ignored, exit 0.
* ``tests/c_host/abu_cosim_host.c`` (libcosimc, the library of libcosimpy's wheel) runs the
  report's staircase exported as SSP with the native FMUs: the same slip time and bounds as
  with the Python FMUs in the same host.

In both, the dynamic loader's own trace (``LD_DEBUG=libs``) shows that no libpython is ever
loaded, in an environment without any PYTHON* variable or LD_PRELOAD.
"""
from __future__ import annotations

import math
import os
import shutil
import subprocess
import zipfile

import pytest
from fmpy import read_model_description

from test_ssp import compile_c_host, host_env, parse_host_line

from test_fmu_native import HOST


@pytest.fixture(scope="module")
def bare_host(tmp_path_factory):
    cc = shutil.which("cc") or shutil.which("gcc")
    assert cc, "no C compiler: the native build needs one too"
    exe = tmp_path_factory.mktemp("host") / "fmu_c_host"
    subprocess.run([cc, "-O1", "-o", str(exe), str(HOST), "-ldl", "-lm"], check=True)
    return exe


def _traced_env() -> dict[str, str]:
    env = {k: v for k, v in host_env().items() if not k.startswith("PYTHON")}
    env["LD_DEBUG"] = "libs"  # the loader lists every library it loads on stderr
    return env


def _loaded_python(stderr: str) -> list[str]:
    return [line for line in stderr.splitlines() if "libpython" in line]


@pytest.mark.parametrize("name, variable, expected", [
    ("AbuBall", "omega", -2 * math.pi * 17),           # no torque: the rotor keeps its speed
    ("Staircase", "omega_ref", -2 * math.pi * 18),     # lead rounding: first step at t0 = 0
    ("SpeedController", "x_I", 0.0),                   # zero inputs: the integrator stays put
])
def test_bare_c_host_runs_native_fmu_without_python(native_fmu_dir, tmp_path, bare_host, name,
                                                     variable, expected):
    with zipfile.ZipFile(native_fmu_dir[name]) as z:
        z.extractall(tmp_path)
    md = read_model_description(str(native_fmu_dir[name]))
    vr = next(v.valueReference for v in md.modelVariables if v.name == variable)
    binary = tmp_path / "binaries" / "linux64" / f"{name}.so"
    args = [str(bare_host), str(binary), str(tmp_path / "resources"), md.guid, "100", str(vr)]
    done = subprocess.run(args + ["bad"], capture_output=True, text=True, env=_traced_env(),
                          timeout=120)
    assert done.returncode == 0, done.stdout + done.stderr[-2000:]
    assert "AbuBall.so" in done.stderr or name != "AbuBall"  # the trace is there
    assert not _loaded_python(done.stderr)
    lines = done.stdout.splitlines()
    value = float(next(line.split()[1] for line in lines if line.startswith("value ")))
    assert value == pytest.approx(expected, rel=1e-12, abs=1e-12)
    statuses = dict(line.split()[1:3] for line in lines if line.startswith("status "))
    assert statuses == {"early-step": "3", "nan-step": "3", "wrong-time": "3", "garbage-state": "3",
                        "set-garbage-pointer": "3", "unknown-vr": "3", "null-values": "3",
                        "step-after-errors": "0"}, done.stdout
    assert len([line for line in lines if line.startswith("log host 3 ")]) == 7, done.stdout
    assert lines[-1] == "done"


def test_libcosim_host_runs_the_report_staircase_on_native_fmus(native_fmu_dir, fmu_dir,
                                                                tmp_path):
    from abu_model.params import PlantParams
    from fmus.ssp import Experiment, write_ssp
    from harness.experiments.staircase import StaircaseExperiment

    exe = compile_c_host(tmp_path)
    exp = StaircaseExperiment(PlantParams(), -17 * 2 * math.pi, -22 * 2 * math.pi,
                              comm_step=1e-3)
    steps = round((exp.t_end - exp.t_start) / exp.comm_step)
    got = {}
    for label, fmus in (("native", native_fmu_dir), ("python", fmu_dir)):
        system = exp.system(fmus)
        ssp = write_ssp(tmp_path / f"{label}.ssp", system.components, system.connections,
                        Experiment(exp.t_start, exp.t_end, exp.comm_step))
        proc = subprocess.run([str(exe), str(ssp), str(steps)], capture_output=True, text=True,
                              timeout=300, env=_traced_env() if label == "native" else host_env())
        assert proc.returncode == 0, proc.stderr[-2000:]
        if label == "native":
            assert "libcosimc" in proc.stderr and not _loaded_python(proc.stderr)
        got[label] = parse_host_line(proc.stdout)
    print(f"\nlibcosimc host, report staircase at 1 ms: native {got['native']}, "
          f"python {got['python']}")
    assert got["native"] == got["python"]
    assert 0.55 <= got["native"]["t_slip"] <= 0.553
