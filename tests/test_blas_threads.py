"""Every entry point (the ``abu`` command, ``measurement``, ``harness``) asks for one BLAS
thread before NumPy loads, and keeps a user's own setting.

Why it matters: the analysis' matrices are small, and a multi-threaded OpenBLAS on a busy
machine is several times slower on them (``abu measure --no-plots`` on 3072 frames: 2.9-4.3 s
against 1.0 s with one thread, on a 2-core machine with two other busy processes). The check
runs in fresh interpreters without the variable (this test session sets it in conftest).
"""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PROBE = ("import os, sys\n"
         "import {module}\n"
         "print(os.environ.get('OPENBLAS_NUM_THREADS'), 'numpy' in sys.modules)\n"
         "import numpy\n")


def _probe(module: str, value: str | None) -> tuple[str, str]:
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    env["PYTHONPATH"] = str(ROOT)
    if value is not None:
        env["OPENBLAS_NUM_THREADS"] = value
    out = subprocess.run([sys.executable, "-c", PROBE.format(module=module)], env=env,
                         capture_output=True, text=True, check=True).stdout.split()
    return out[0], out[1]


@pytest.mark.parametrize("module", ["abu", "abu.cli.main", "measurement", "harness"])
def test_one_blas_thread_is_asked_before_numpy_loads(module):
    threads, _ = _probe(module, None)
    assert threads == "1", f"import {module} left OPENBLAS_NUM_THREADS at {threads}"


@pytest.mark.parametrize("module", ["abu", "measurement", "harness"])
def test_the_package_file_sets_it_before_anything_loads_numpy(module):
    # the package file itself must not load NumPy (else the setting comes too late for it)
    _, numpy_loaded = _probe(module, None)
    assert numpy_loaded == "False", f"import {module} loads NumPy"


def test_a_users_own_setting_is_kept():
    assert _probe("abu.cli.main", "3")[0] == "3"
    assert _probe("measurement", "2")[0] == "2"
