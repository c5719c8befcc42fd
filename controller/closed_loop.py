"""The identified closed loop as a python-control transfer function (report eq. 4.5)."""
from __future__ import annotations

import control

from .pi import PISpeedController


def speed_transfer_function(ctrl: PISpeedController) -> control.TransferFunction:
    ("""omega(s) / omega_ref(s) = (2 zeta wn s + wn^2) / (s^2 + 2 zeta wn s + wn^2) """
     """(integral mode).""")
    z, wn = ctrl.zeta, ctrl.omega_n
    return control.tf([2.0 * z * wn, wn**2], [1.0, 2.0 * z * wn, wn**2])


def acceleration_transfer_function(ctrl: PISpeedController) -> control.TransferFunction:
    ("""alpha(s) / omega_ref(s) = s omega(s)/omega_ref(s) [1/s]: its value at t=0+ of a unit """
     """step is 2 zeta wn.""")
    z, wn = ctrl.zeta, ctrl.omega_n
    return control.tf([2.0 * z * wn, wn**2, 0.0], [1.0, 2.0 * z * wn, wn**2])
