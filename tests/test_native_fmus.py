"""The native FMUs (fmus/native_build.py, C under fmus/native_c): a drop-in for the Python
FMUs.

Checked here: fmpy's validation finds nothing; the model description is the Python FMU's
(variables, value references, causalities, variabilities, units, start values, structure)
with its own guid, no Python requirement and the C sources listed; every parameter's value
before initialization is its start value; the binary needs libm and libc only; and the
builder's errors (no compiler, no cross compiler) are clear and write nothing.
"""
from __future__ import annotations

import subprocess
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

import pytest
from fmpy import read_model_description, simulate_fmu
from fmpy.validation import validate_fmu

NAMES = ("AbuBall", "SpeedController", "Staircase")


@pytest.mark.parametrize("name", NAMES)
def test_fmpy_validation_reports_nothing(native_fmu_dir, name):
    assert validate_fmu(str(native_fmu_dir[name])) == []


def _variables(path: Path) -> list[tuple]:
    md = read_model_description(str(path))
    return [(v.name, v.valueReference, v.type, v.causality, v.variability, v.initial,
             v.unit, v.start, v.description) for v in md.modelVariables]


@pytest.mark.parametrize("name", NAMES)
def test_model_description_is_the_python_fmus_with_its_own_guid(native_fmu_dir, fmu_dir, name):
    assert _variables(native_fmu_dir[name]) == _variables(fmu_dir[name])
    native = read_model_description(str(native_fmu_dir[name]))
    python = read_model_description(str(fmu_dir[name]))
    assert native.guid != python.guid
    assert [(u.variable.name, [d.name for d in u.dependencies]) for u in native.outputs] == \
        [(u.variable.name, [d.name for d in u.dependencies]) for u in python.outputs]
    cs = native.coSimulation
    assert not cs.needsExecutionTool and cs.canGetAndSetFMUstate and cs.canSerializeFMUstate
    with zipfile.ZipFile(native_fmu_dir[name]) as z:
        names = z.namelist()
        root = ET.fromstring(z.read("modelDescription.xml"))
    listed = [f.get("name") for f in root.iter("File")]
    assert listed and all(f"sources/{f}" in names for f in listed)
    assert "sources/fmi2Functions.h" in names and "sources/LICENSE-FMI2-HEADERS.txt" in names
    assert not any(n.startswith("resources/") or n.endswith(".py") for n in names)


@pytest.mark.parametrize("name", NAMES)
def test_start_values_are_the_binarys_values(native_fmu_dir, name):
    from fmpy import extract
    from fmpy.fmi2 import FMU2Slave

    md = read_model_description(str(native_fmu_dir[name]))
    unzipdir = extract(str(native_fmu_dir[name]))
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir,
                    modelIdentifier=md.coSimulation.modelIdentifier, instanceName="starts")
    fmu.instantiate()
    for v in md.modelVariables:
        if v.start is None:
            continue
        get, parse = {"Real": (fmu.getReal, float), "Integer": (fmu.getInteger, int),
                      "Boolean": (fmu.getBoolean, lambda s: s == "true")}[v.type]
        assert get([v.valueReference])[0] == parse(v.start), v.name
    fmu.freeInstance()


@pytest.mark.parametrize("name", NAMES)
def test_binary_needs_only_libm_and_libc(native_fmu_dir, tmp_path, name):
    with zipfile.ZipFile(native_fmu_dir[name]) as z:
        z.extract(f"binaries/linux64/{name}.so", tmp_path)
    ldd = subprocess.run(["ldd", str(tmp_path / "binaries" / "linux64" / f"{name}.so")],
                         capture_output=True, text=True).stdout
    needed = {line.split()[0] for line in ldd.splitlines() if "=>" in line}
    assert needed <= {"libm.so.6", "libc.so.6"}, ldd


def test_fmpy_simulates_the_staircase_fmu(native_fmu_dir):
    result = simulate_fmu(str(native_fmu_dir["Staircase"]), stop_time=1.2, output_interval=1e-3,
                          output=["omega_ref", "step_index"])
    assert result["step_index"][-1] == 5  # -17 Hz -> -22 Hz in 1 Hz steps


def test_no_compiler_is_a_clear_error_and_writes_nothing(tmp_path, monkeypatch):
    from fmus.model_description import FmuBuildError
    from fmus.native_build import build_native_fmus

    monkeypatch.setenv("CC", str(tmp_path / "no-such-cc"))
    with pytest.raises(FmuBuildError, match="C compiler in CC"):
        build_native_fmus(tmp_path / "out", win64=False)
    assert not list((tmp_path / "out").glob("*"))
    monkeypatch.delenv("CC")
    monkeypatch.setenv("PATH", str(tmp_path))  # no cross compiler either
    with pytest.raises(FmuBuildError, match="mingw"):
        build_native_fmus(tmp_path / "out", win64=True)


def _fmutool() -> Path | None:
    """fmu-manipulation-toolbox's command line (a test extra), next to this interpreter."""
    import shutil
    import sys

    found = Path(sys.executable).parent / "fmutool"
    return found if found.is_file() else (Path(shutil.which("fmutool"))
                                          if shutil.which("fmutool") else None)


@pytest.mark.parametrize("name", NAMES)
def test_fmu_manipulation_toolbox_checker_reports_nothing(native_fmu_dir, name):
    tool = _fmutool()
    if tool is None:
        pytest.skip("fmu-manipulation-toolbox is not installed (pip install -e '.[test]')")
    done = subprocess.run([str(tool), "-input", str(native_fmu_dir[name]), "-check"],
                          capture_output=True, text=True, timeout=120)
    out = done.stdout + done.stderr  # it exits 0 either way: read its verdicts
    assert "This FMU seems to be compliant with FMI-2.0." in out, out
    assert "No semantic error against the FMI-2 standard." in out, out
    assert not [line for line in out.splitlines()
                if line.split("|")[0].strip() in ("WARNING", "ERROR", "CRITICAL")], out
