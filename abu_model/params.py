"""Ball and plant parameters (SI units) with validation.

Defaults are the report's values (Suy, DCT 2003-22, sec. 3.3): a brass ball of
m = 1.4e-4 kg, d = 3.0e-3 m whose centre runs at l = 1.15e-2 m from the ABU axis, and the
static friction coefficient mu = 2.75e-3 of the report's simulations (sec. 4.2.3).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

from .errors import ParameterError

#: Rotor inertia [kg m^2] used when the ball's reaction on the rotor is switched on. The
#: report gives none: a CD (15.5 g, radii 7.5-60 mm) has 2.8e-5 kg m^2, the ABU disc and the
#: motor rotor add about 1.7e-5 kg m^2. The closed loop does not depend on it (the PI gains
#: scale with it); only the ball's reaction does, as m l^2 / J_abu ~ 4e-4.
DEFAULT_J_ABU = 4.5e-5

#: Fastest frame rate taken as a camera's [frames/s]: burst cameras reach 1e7 frames/s
#: (e.g. Shimadzu HPV-X2); every reader, option and plan checks against this one figure.
MAX_CAMERA_FPS_HZ = 1.0e7


def check_finite(name: str, value: Any, expected: str = "a finite number") -> float:
    """Return ``value`` as float, or raise :class:`ParameterError` if it is not finite."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ParameterError(name, value, expected) from None
    if not math.isfinite(number):
        raise ParameterError(name, value, expected)
    return number


def check_positive(name: str, value: Any, unit: str) -> float:
    """Return ``value`` as float if finite and > 0, else raise :class:`ParameterError`."""
    number = check_finite(name, value, f"a finite number > 0 {unit}".rstrip())
    if number <= 0.0:
        raise ParameterError(name, value, f"a finite number > 0 {unit}".rstrip())
    return number


def check_nonnegative(name: str, value: Any, unit: str) -> float:
    """Return ``value`` as float if finite and >= 0, else raise :class:`ParameterError`."""
    number = check_finite(name, value, f"a finite number >= 0 {unit}".rstrip())
    if number < 0.0:
        raise ParameterError(name, value, f"a finite number >= 0 {unit}".rstrip())
    return number


@dataclass(frozen=True)
class BallParams:
    """One ball on the rim of the ABU.

    Attributes:
        m: ball mass [kg].
        d: ball diameter [m].
        l: radius of the ball centre's path [m]; must exceed d/2.
        mu: static friction coefficient [-].
        mu_d: dynamic (sliding) friction coefficient [-]; ``None`` means equal to ``mu``
            (the report's choice). Must not exceed ``mu``.
    """

    m: float = 1.4e-4
    d: float = 3.0e-3
    l: float = 1.15e-2
    mu: float = 2.75e-3
    mu_d: float | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "m", check_positive("m", self.m, "kg"))
        object.__setattr__(self, "d", check_positive("d", self.d, "m"))
        object.__setattr__(self, "l", check_positive("l", self.l, "m"))
        if self.d >= 2.0 * self.l:
            raise ParameterError("d", self.d, f"a diameter < 2 l = {2.0 * self.l:g} m")
        object.__setattr__(self, "mu", check_nonnegative("mu", self.mu, ""))
        if self.mu_d is not None:
            mu_d = check_nonnegative("mu_d", self.mu_d, "")
            if mu_d > self.mu:
                raise ParameterError(
                    "mu_d", self.mu_d,
                    f"a value <= mu = {self.mu:g} (sliding friction above static friction "
                    "leaves the stick/slip transition without a consistent solution)")
            object.__setattr__(self, "mu_d", mu_d)

    @property
    def mu_dynamic(self) -> float:
        """Sliding friction coefficient in use [-] (``mu`` when ``mu_d`` is None)."""
        return self.mu if self.mu_d is None else self.mu_d

    @property
    def J(self) -> float:
        """Ball's moment of inertia about its centre, m d^2 / 10 [kg m^2]."""
        return self.m * self.d**2 / 10.0

    @property
    def M_bb(self) -> float:
        """Generalised mass of beta, m l^2 + J (2l/d)^2 = 1.4 m l^2 [kg m^2]."""
        return self.m * self.l**2 + self.J * (2.0 * self.l / self.d) ** 2

    @property
    def coupling(self) -> float:
        """Inertial coupling of beta and theta, m l^2 - J 2l/d = m l (l - d/5) [kg m^2]."""
        return self.m * self.l**2 - self.J * 2.0 * self.l / self.d

    @property
    def lever_ratio(self) -> float:
        """(l - d/5) / l [-]: the factor between |alpha| / omega^2 and mu_req."""
        return (self.l - self.d / 5.0) / self.l

    def with_(self, **changes: Any) -> "BallParams":
        """A copy with ``changes`` applied (validated again)."""
        return replace(self, **changes)


@dataclass(frozen=True)
class PlantParams:
    """The ABU rotor with one ball.

    Attributes:
        ball: the ball.
        J_abu: rotor inertia [kg m^2] (CD, ABU disc, motor rotor).
        tau_motor: time constant of the first-order lag from commanded to applied torque
            [s]; 0 (default) applies the commanded torque at once, as in the report.
        ball_reaction: if True the ball's inertial reaction acts on the rotor (full coupled
            Lagrangian); False (default) is the report's decoupled model.
    """

    ball: BallParams = field(default_factory=BallParams)
    J_abu: float = DEFAULT_J_ABU
    tau_motor: float = 0.0
    ball_reaction: bool = False

    def __post_init__(self) -> None:
        if not isinstance(self.ball, BallParams):
            raise ParameterError("ball", self.ball, "a BallParams instance")
        object.__setattr__(self, "J_abu", check_positive("J_abu", self.J_abu, "kg m^2"))
        object.__setattr__(self, "tau_motor",
                           check_nonnegative("tau_motor", self.tau_motor, "s"))
        object.__setattr__(self, "ball_reaction", bool(self.ball_reaction))

    @property
    def J_total(self) -> float:
        """Rotor inertia seen by the torque when the ball sticks [kg m^2].

        J_abu + m l^2 + J with the ball's reaction, J_abu without.
        """
        b = self.ball
        return self.J_abu + (b.m * b.l**2 + b.J if self.ball_reaction else 0.0)


def check_record(record: Any, kinds: dict[str, str], what: str) -> dict[str, Any]:
    """Validate a saved record (a dict, e.g. an FMU state read back from JSON).

    ``kinds`` maps each required key to ``"real"`` (finite float), ``"extended"`` (float,
    +-inf allowed, not NaN), ``"int"`` or ``"bool"``. Returns a new dict with exactly those
    keys and normalised types; raises ``ValueError`` naming the first bad key.
    """
    if not isinstance(record, dict):
        raise ValueError(f"{what}: expected a mapping, got {type(record).__name__}")
    out: dict[str, Any] = {}
    for key, kind in kinds.items():
        if key not in record:
            raise ValueError(f"{what}: '{key}' is missing")
        value = record[key]
        if kind == "bool":
            if not isinstance(value, bool):
                raise ValueError(f"{what}: '{key}' = {value!r} is not a boolean")
        elif kind == "int":
            if isinstance(value, bool) or not isinstance(value, int) or abs(value) > 2**31 - 1:
                raise ValueError(f"{what}: '{key}' = {value!r} is not a 32-bit integer")
        else:
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ValueError(f"{what}: '{key}' = {value!r} is not a number")
            value = float(value)
            if math.isnan(value) or (kind == "real" and math.isinf(value)):
                raise ValueError(f"{what}: '{key}' = {value!r} is not a finite number")
        out[key] = value
    return out
