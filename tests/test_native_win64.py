"""The native FMUs' win64 binaries: cross-compiled with mingw-w64 and run under wine.

``tests/c_host/native_staircase_host.c`` (a portable fixed-step FMI host: LoadLibrary on
Windows, dlopen on Linux) runs the report's staircase at 1 ms once as a Linux program on the
linux64 binaries and once as a win64 program (cross-compiled, statically linked) under wine
on the win64 DLLs of the same FMUs: the same output line (slip time and bounds). Skipped
only when mingw-w64 or wine is missing on this machine; .ci/run installs both.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import zipfile
from pathlib import Path

import pytest
from fmpy import read_model_description

HOST = Path(__file__).resolve().parent / "c_host" / "native_staircase_host.c"
INCLUDE = Path(__file__).resolve().parent.parent / "fmus" / "native_c"
ORDER = ("AbuBall", "SpeedController", "Staircase")  # the host's argument order
MINGW = "x86_64-w64-mingw32-gcc"


def _wine() -> str | None:
    return shutil.which("wine64") or shutil.which("wine") or (
        "/usr/lib/wine/wine64" if os.access("/usr/lib/wine/wine64", os.X_OK) else None)


def _host_line(stdout: str) -> dict[str, float]:
    line = next(line for line in stdout.splitlines() if line.startswith("t_slip="))
    return {k: float(v) for k, v in (item.split("=") for item in line.strip().split())}


def test_win64_binaries_under_wine_give_the_linux_slip(tmp_path):
    wine = _wine()
    if shutil.which(MINGW) is None or wine is None:
        pytest.skip(f"needs {MINGW} and wine (apt-get install gcc-mingw-w64-x86-64 wine64)")
    from fmus.native_build import build_native_fmus

    fmus = build_native_fmus(tmp_path / "fmus", win64=True)
    args = {"linux64": [], "win64": []}
    for name in ORDER:
        with zipfile.ZipFile(fmus[name]) as z:
            z.extractall(tmp_path / name)
        guid = read_model_description(str(fmus[name])).guid
        args["linux64"] += [str(tmp_path / name / "binaries" / "linux64" / f"{name}.so"), guid]
        args["win64"] += [f"{name}\\binaries\\win64\\{name}.dll", guid]  # relative to cwd
    linux_exe, win_exe = tmp_path / "host", tmp_path / "host.exe"
    subprocess.run([shutil.which("cc") or "gcc", "-std=c99", "-O1", "-I", str(INCLUDE), "-o",
                    str(linux_exe), str(HOST), "-ldl", "-lm"], check=True)
    subprocess.run([MINGW, "-std=c99", "-O1", "-static", "-I", str(INCLUDE), "-o", str(win_exe),
                    str(HOST)], check=True)
    linux = subprocess.run([str(linux_exe), *args["linux64"], "1550"], capture_output=True,
                           text=True, timeout=120)
    assert linux.returncode == 0, linux.stderr
    env = {**os.environ, "WINEDEBUG": "-all", "WINEPREFIX": str(tmp_path / "wineprefix")}
    windows = subprocess.run([wine, str(win_exe), *args["win64"], "1550"], capture_output=True,
                             text=True, timeout=600, cwd=tmp_path, env=env)
    assert windows.returncode == 0, windows.stdout + windows.stderr[-2000:]
    got_linux, got_windows = _host_line(linux.stdout), _host_line(windows.stdout)
    print(f"\nreport staircase at 1 ms: linux64 {got_linux}, win64 under wine {got_windows}")
    assert got_windows == got_linux
    assert 0.55 <= got_linux["t_slip"] <= 0.553
