"""Parameter validation and the model's derived quantities against the report's formulas."""
import math

import numpy as np
import pytest

from abu_model.errors import ParameterError
from abu_model.params import BallParams, PlantParams


@pytest.mark.parametrize("kwargs, name", [
    ({"m": -1e-4}, "m"), ({"m": 0.0}, "m"), ({"d": float("nan")}, "d"),
    ({"l": float("inf")}, "l"), ({"d": 0.03, "l": 0.015}, "d"), ({"mu": -0.1}, "mu"),
    ({"mu_d": -0.001}, "mu_d"), ({"mu": 0.01, "mu_d": 0.02}, "mu_d"), ({"m": "heavy"}, "m"),
])
def test_bad_ball_parameters_name_the_parameter(kwargs, name):
    with pytest.raises(ParameterError) as info:
        BallParams(**kwargs)
    assert info.value.parameter == name
    assert f"'{name}'" in str(info.value)


@pytest.mark.parametrize("kwargs, name", [
    ({"J_abu": -1.0}, "J_abu"), ({"tau_motor": -1e-3}, "tau_motor"),
    ({"tau_motor": float("nan")}, "tau_motor"),
])
def test_bad_plant_parameters_name_the_parameter(kwargs, name):
    with pytest.raises(ParameterError) as info:
        PlantParams(**kwargs)
    assert info.value.parameter == name


def test_derived_inertias_match_report_closed_forms():
    b = BallParams()
    # J = m d^2 / 10, M_bb = m l^2 + J (2l/d)^2 = 1.4 m l^2, c = m l^2 - J 2l/d = m l (l - d/5)
    assert b.J == pytest.approx(1.4e-4 * 9e-6 / 10, rel=1e-15)
    assert b.M_bb == pytest.approx(1.4 * b.m * b.l**2, rel=1e-14)
    assert b.coupling == pytest.approx(b.m * b.l * (b.l - b.d / 5), rel=1e-14)
    assert b.mu_dynamic == b.mu
    assert BallParams(mu=0.01, mu_d=0.005).mu_dynamic == 0.005


def test_ball_reaction_adds_ball_inertia_only_when_on():
    off, on = PlantParams(), PlantParams(ball_reaction=True)
    b = off.ball
    assert off.J_total == off.J_abu
    assert on.J_total - on.J_abu == pytest.approx(b.m * b.l**2 + b.J, rel=1e-14)
    assert (on.J_total - on.J_abu) / on.J_abu < 1e-3  # the report's "negligible"


def test_atomic_write_leaves_nothing_on_error_and_ordinary_permissions(tmp_path):
    import os
    import stat

    from abu_model.atomic_io import atomic_open, atomic_write_text

    target = tmp_path / "out.txt"
    atomic_write_text(target, "first")
    with pytest.raises(RuntimeError):
        with atomic_open(target, "w") as handle:
            handle.write("half")
            raise RuntimeError("failure while writing")
    assert target.read_text() == "first"
    assert [p.name for p in tmp_path.iterdir()] == ["out.txt"]  # no temporary file left
    mask = os.umask(0)
    os.umask(mask)
    assert stat.S_IMODE(target.stat().st_mode) == 0o666 & ~mask
