"""Shared fixtures.

``fmu_dir`` builds the toolkit's three FMUs once per test session (building takes about a
second each) into a temporary folder and returns ``{name: path}`` for AbuBall, SpeedController
and Staircase.
"""
from __future__ import annotations

from pathlib import Path

import pytest


@pytest.fixture(scope="session")
def fmu_dir(tmp_path_factory) -> dict[str, Path]:
    """Paths of AbuBall.fmu, SpeedController.fmu and Staircase.fmu, built once per session."""
    from fmus.build import build_fmus

    return build_fmus(tmp_path_factory.mktemp("fmus"))
