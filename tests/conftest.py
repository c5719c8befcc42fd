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
