"""Shared fixtures.

``fmu_dir`` builds the toolkit's three FMUs once per test session (building takes about a
second each) into a temporary folder and returns ``{name: path}`` for AbuBall, SpeedController
and Staircase.
"""
from __future__ import annotations

import os

# Before NumPy loads: multi-threaded BLAS is slower on the small problems here (see harness).
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from pathlib import Path

import pytest


@pytest.fixture(scope="session")
def fmu_dir(tmp_path_factory) -> dict[str, Path]:
    """Paths of AbuBall.fmu, SpeedController.fmu and Staircase.fmu, built once per session."""
    from fmus.build import build_fmus

    return build_fmus(tmp_path_factory.mktemp("fmus"))


@pytest.fixture(scope="session")
def native_fmu_dir(tmp_path_factory) -> dict[str, Path]:
    """The native (Python-free) AbuBall, SpeedController and Staircase FMUs, built once per
    session (linux64 only; the win64 test builds its own)."""
    from fmus.native_build import build_native_fmus

    return build_native_fmus(tmp_path_factory.mktemp("native_fmus"), win64=False)
