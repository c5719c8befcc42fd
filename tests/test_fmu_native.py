"""A non-Python host loads the FMUs without LD_PRELOAD and exits cleanly.

``tests/fmu_c_host.c`` (compiled here with the system C compiler) dlopens an FMU's binary in a
process without libpython, runs 100 steps of 1 ms, prints a value, makes a series of host
mistakes (doStep before initialisation, NaN and wrong times, a garbage serialized state, an
unknown state pointer, an unknown value reference, a NULL array) and frees the instance twice.
"""
from __future__ import annotations

import math
import os
import shutil
import subprocess
import zipfile
from pathlib import Path

import pytest
from fmpy import read_model_description

HOST = Path(__file__).resolve().parent / "fmu_c_host.c"
RUNS = 10  # per FMU: every run must exit 0 (the exit-time crash of pythonfmu was 2 in 70)


@pytest.fixture(scope="module")
def c_host(tmp_path_factory):
    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        pytest.fail("no C compiler: the FMU build needs one too")
    exe = tmp_path_factory.mktemp("host") / "fmu_c_host"
    subprocess.run([cc, "-O1", "-o", str(exe), str(HOST), "-ldl", "-lm"], check=True)
    return exe


def _env():
    return {k: v for k, v in os.environ.items()
            if k not in ("LD_PRELOAD", "PYTHONHOME", "PYTHONPATH", "LD_LIBRARY_PATH")}


@pytest.mark.parametrize("name, variable, expected", [
    ("AbuBall", "omega", -2 * math.pi * 17),           # no torque: the rotor keeps its speed
    ("Staircase", "omega_ref", -2 * math.pi * 18),     # lead rounding: first step at t0 = 0
    ("SpeedController", "x_I", 0.0),                   # zero inputs: the integrator stays put
])
def test_c_host_runs_the_fmu_without_preload_and_survives_mistakes(fmu_dir, tmp_path, c_host,
                                                                   name, variable, expected):
    with zipfile.ZipFile(fmu_dir[name]) as z:
        z.extractall(tmp_path)
    md = read_model_description(str(fmu_dir[name]))
    vr = next(v.valueReference for v in md.modelVariables if v.name == variable)
    binary = tmp_path / "binaries" / "linux64" / f"{name}.so"
    assert b"libpython" not in subprocess.run(["ldd", str(c_host)], capture_output=True).stdout
    args = [str(c_host), str(binary), str(tmp_path / "resources"), md.guid, "100", str(vr)]
    done = subprocess.run(args + ["bad"], capture_output=True, text=True, env=_env(), timeout=120)
    assert done.returncode == 0, done.stdout + done.stderr
    lines = done.stdout.splitlines()
    value = float(next(line.split()[1] for line in lines if line.startswith("value ")))
    assert value == pytest.approx(expected, rel=1e-12, abs=1e-12)
    statuses = dict(line.split()[1:3] for line in lines if line.startswith("status "))
    assert statuses == {"early-step": "3", "nan-step": "3", "wrong-time": "3", "garbage-state": "3",
                        "set-garbage-pointer": "3", "unknown-vr": "3", "null-values": "3",
                        "step-after-errors": "0"}, done.stdout
    errors = [line for line in lines if line.startswith("log host 3 ")]
    assert len(errors) == 7, done.stdout  # each refused call logged why
    assert lines[-1] == "done"
    for _ in range(RUNS):
        again = subprocess.run(args, capture_output=True, text=True, env=_env(), timeout=120)
        assert again.returncode == 0 and again.stdout.endswith("done\n"), again.stdout + again.stderr


def test_build_without_the_c_compiler_is_a_clear_error_and_writes_nothing(tmp_path, monkeypatch):
    from fmus.build import build_fmu
    from fmus.model_description import FmuBuildError

    monkeypatch.setenv("CC", str(tmp_path / "no-such-cc"))
    with pytest.raises(FmuBuildError, match="C compiler in CC"):
        build_fmu("Staircase", tmp_path / "out")
    assert not list((tmp_path / "out").glob("*"))
