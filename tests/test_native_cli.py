"""The native FMUs (issue 21) from the command line: ``abu build-fmus --native``, ``abu
export-ssp --native`` in libcosimpy and fmpy.ssp, ``abu simulate`` and ``abu sweep`` on a
native ``--fmu-dir``; a folder that mixes the two builds or lacks a native FMU is refused.

Truths: the same commands on the Python (pythonfmu) FMUs, the second implementation of the
same physics (tests/test_native_agreement.py: equal to the last bit in our master), and
``fmpy validate`` for the built files.
"""
from __future__ import annotations

import csv
import json
import shutil
import zipfile
from pathlib import Path

import pytest
from fmpy.validation import validate_fmu

from abu.cli.main import main
from fmus.native_build import is_native_fmu
from test_ssp import FMPY_CHILD, LIBCOSIM_CHILD, _child, _last_json, _steps, first_slip
from fmus.ssp import read_default_experiment

NAMES = ("AbuBall", "SpeedController", "Staircase")
#: The report's staircase (the defaults): the ball slips at a setpoint step, both bounds.
SIMULATE = ["simulate", "--json"]


@pytest.fixture(scope="module")
def native_folder(tmp_path_factory) -> Path:
    """``abu build-fmus --native --out DIR`` (linux64, win64 when mingw-w64 is installed)."""
    out = tmp_path_factory.mktemp("cli") / "native"
    assert main(["build-fmus", "--native", "--out", str(out)]) == 0
    return out


@pytest.fixture(scope="module")
def python_folder(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("cli") / "python"
    assert main(["build-fmus", "--out", str(out)]) == 0
    return out


def _summary(capsys, argv: list[str]) -> dict:
    capsys.readouterr()
    assert main(argv) == 0
    return json.loads(capsys.readouterr().out)


# ---------------------------------------------------------------------------- build-fmus
def test_build_fmus_native_writes_fmus_that_fmpy_validates(native_folder):
    assert sorted(p.name for p in native_folder.iterdir()) == [f"{n}.fmu" for n in NAMES]
    for name in NAMES:
        fmu = native_folder / f"{name}.fmu"
        assert validate_fmu(str(fmu)) == []
        assert is_native_fmu(fmu)
        with zipfile.ZipFile(fmu) as zf:
            names = zf.namelist()
        assert f"binaries/linux64/{name}.so" in names and f"sources/{name.lower()}_fmu.c" in names
        assert not any("python" in n.lower() for n in names)  # no pythonfmu layer inside


def test_build_fmus_native_prints_what_each_fmu_carries(tmp_path, capsys):
    out = tmp_path / "n"
    assert main(["build-fmus", "--native", "--out", str(out)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [line.split(":")[0] for line in lines] == list(NAMES)
    assert all("linux64" in line and "sources" in line for line in lines)


def test_python_build_is_not_native(python_folder):
    assert not any(is_native_fmu(python_folder / f"{n}.fmu") for n in NAMES)


# ---------------------------------------------------------------------------- simulate, sweep
def test_simulate_on_a_native_fmu_dir_gives_the_python_fmus_summary(native_folder,
                                                                    python_folder, capsys):
    before = {p.name: p.read_bytes() for p in native_folder.iterdir()}
    native = _summary(capsys, [*SIMULATE, "--fmu-dir", str(native_folder)])
    python = _summary(capsys, [*SIMULATE, "--fmu-dir", str(python_folder)])
    assert native["t_slip"] is not None and native["mu_low"] < native["mu"] < native["mu_high"]
    # every field (bounds, switch times, step statistics) equal: the same physics to the bit
    assert native == python
    # nothing was built into (or over) the native folder
    assert {p.name: p.read_bytes() for p in native_folder.iterdir()} == before


def test_sweep_on_a_native_fmu_dir_keeps_it_and_matches_the_python_fmus(native_folder,
                                                                       python_folder, tmp_path):
    before = {p.name: p.read_bytes() for p in native_folder.iterdir()}
    rows = {}
    for label, folder in (("native", native_folder), ("python", python_folder)):
        out = tmp_path / f"{label}.csv"
        assert main(["sweep", "--mu", "2.75e-3", "--omega0-hz", "-17", "--workers", "1",
                     "--out", str(out), "--fmu-dir", str(folder)]) == 0
        rows[label] = list(csv.DictReader(out.open()))
    assert rows["native"] == rows["python"] and rows["native"][0]["bracketed"] == "True"
    assert {p.name: p.read_bytes() for p in native_folder.iterdir()} == before


@pytest.mark.parametrize("command", [SIMULATE, ["table41", "--mu", "2.75e-3"],
                                     ["sweep", "--mu", "2.75e-3", "--omega0-hz", "-17",
                                      "--out", "SWEEP"]])
def test_a_folder_mixing_builds_or_lacking_a_native_fmu_is_refused(
        command, native_folder, python_folder, tmp_path, capsys):
    mixed, partial = tmp_path / "mixed", tmp_path / "partial"
    mixed.mkdir()
    partial.mkdir()
    shutil.copy(native_folder / "AbuBall.fmu", mixed)
    shutil.copy(python_folder / "SpeedController.fmu", mixed)
    shutil.copy(native_folder / "AbuBall.fmu", partial)
    shutil.copy(native_folder / "Staircase.fmu", partial)
    argv = [str(tmp_path / "s.csv") if a == "SWEEP" else a for a in command]
    for folder, says in ((mixed, "SpeedController.fmu is not"),
                         (partial, "SpeedController.fmu is missing")):
        contents = sorted(p.name for p in folder.iterdir())
        assert main([*argv, "--fmu-dir", str(folder)]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "--fmu-dir" in err and says in err, err
        assert "abu build-fmus --native" in err
        # nothing built into the folder, nothing written
        assert sorted(p.name for p in folder.iterdir()) == contents
        assert not (tmp_path / "s.csv").exists()


# ---------------------------------------------------------------------------- export-ssp
@pytest.fixture(scope="module")
def exports(tmp_path_factory) -> dict[str, Path]:
    """The default export of each build."""
    folder = tmp_path_factory.mktemp("ssp")
    out = {"native": folder / "native.ssp", "python": folder / "python.ssp"}
    assert main(["export-ssp", "--native", "--out", str(out["native"])]) == 0
    assert main(["export-ssp", "--out", str(out["python"])]) == 0
    return out


def test_export_ssp_native_packages_the_native_fmus(exports, tmp_path):
    with zipfile.ZipFile(exports["native"]) as native, \
            zipfile.ZipFile(exports["python"]) as python:
        assert sorted(native.namelist()) == sorted(python.namelist())
        # the system and its parameter set are the same document
        assert native.read("resources/abu.ssv") == python.read("resources/abu.ssv")
        for name in NAMES:
            member = f"resources/{name}.fmu"
            native.extract(member, tmp_path / "n")
            python.extract(member, tmp_path / "p")
            assert is_native_fmu(tmp_path / "n" / member)
            assert not is_native_fmu(tmp_path / "p" / member)


def _host_rows(code: str, ssp: Path, *args: str) -> dict:
    proc = _child(code, str(ssp), *args)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return _last_json(proc.stdout)


@pytest.mark.parametrize("host", ["fmpy.ssp", "libcosimpy"])
def test_the_native_ssp_runs_in_other_hosts_like_the_python_ssp(host, exports):
    """fmpy.ssp and libcosimpy (``from_ssp_file``) run both archives at the export's fixed step:
    every recorded step of the native archive equals the Python archive's."""
    code = FMPY_CHILD if host == "fmpy.ssp" else LIBCOSIM_CHILD
    extra = () if host == "fmpy.ssp" else (str(_steps(read_default_experiment(
        exports["python"]))),)
    rows = {label: _host_rows(code, ssp, *extra) for label, ssp in exports.items()}
    native, python = rows["native"], rows["python"]
    assert len(native["time"]) == len(python["time"]) > 1000
    slip_n, slip_p = first_slip(native), first_slip(python)
    diff = max(abs(a - b) for key in ("t_last_switch", "mu_req")
               for a, b in zip(native[key], python[key]))
    print(f"\n{host}: native slip at {slip_n['t_slip']:.9f} s, Python {slip_p['t_slip']:.9f} s; "
          f"mu_low {slip_n['mu_low']:.9g} / {slip_p['mu_low']:.9g}; largest difference of "
          f"t_last_switch and mu_req over {len(native['time'])} steps: {diff:.3g}")
    assert native["mode"] == python["mode"]
    assert slip_n == slip_p
    assert native == python
