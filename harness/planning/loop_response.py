"""The closed speed loop's response to a setpoint staircase, for the planning (SI).

The closed-form response lives in :mod:`abu_model.loop_response` (NumPy only, below both
``harness`` and ``measurement``: the measurement's drive-model kinematics use it too); it is
re-exported here with the python-control transfer function of the loop, which the tests
compare with control.forced_response (G(s) and the setpoint filter's pole: see that module).
"""
from __future__ import annotations

from typing import Sequence

import control
import numpy as np

from abu_model.loop_response import (LoopResponse, Setpoints, as_setpoints,  # noqa: F401
                                     loop_polynomials, modes, response, sampled)
from controller.drive import Drive


def loop_tf(zeta: float, omega_n: float, tau: float = 0.0, weight: float = 1.0,
            setpoint_tau: float = 0.0) -> control.TransferFunction:
    """w / w_ref of the loop (with a setpoint filter of time constant ``setpoint_tau`` [s])
    as a python-control transfer function."""
    num, den = loop_polynomials(zeta, omega_n, tau, weight, setpoint_tau)
    return control.tf(list(num), list(den))


def drive_response(drive: Drive, setpoints: Setpoints, t: Sequence[float] | np.ndarray,
                   need_theta: bool = True) -> LoopResponse:
    """:func:`abu_model.loop_response.response` of an identified drive (its setpoint filter
    and, for a digital controller, the steps on its sample grid included)."""
    return response(sampled(setpoints, drive.sample_time), t, drive.zeta, drive.omega_n,
                    drive.tau_motor, drive.setpoint_weight, need_theta,
                    setpoint_tau=drive.setpoint_tau)
