"""The ``profile.json`` schema: a prescribed smooth speed trajectory omega_p(t) (stdlib only).

The report's chapter 6 recommends a controller that tracks a prescribed speed trajectory. A
run of such a drive is a ``drive.json`` of model ``tracking`` (the loop: its bandwidth,
:mod:`controller.drive`) plus this file (the run: which trajectory). ``abu design`` writes it
for a ``tracking`` drive; ``abu simulate``, ``abu render`` and ``abu measure`` read it with
``--profile profile.json``. One JSON object (SI units)::

    {"kind": "abu-profile", "format_version": 1, "interpolation": "cubic-clamped",
     "time_s": [t_0, ..., t_n], "omega_rad_s": [w_0, ..., w_n],
     "units": {...}, "design": {...}, "source": "..."}        (the last three informative)

**Meaning.** omega_p(t) is the cubic spline through the knots (t_k, w_k) with zero slope at
both ends (``cubic-clamped``: C2 inside, C1 everywhere), held at w_0 before t_0 (the drive
has settled there) and at w_n after t_n. So omega_p and its rate (the acceleration the
profile asks for) are continuous: no acceleration steps, unlike the staircase. Times are on
the recording's clock (a measurement fits a small trigger offset). Speeds are all of one sign
(the drive turns one way; negative = clockwise, the report's sign).

Pure Python (no NumPy): the spline's coefficients are solved here (tridiagonal system) so an
FMU can evaluate the profile; :mod:`abu_model.tracking_response` vectorises the same
coefficients.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from controller.json_file import read_json_object

try:  # the shared error type; without abu_model it falls back to ValueError
    from abu_model.errors import AbuError as _Base
except ImportError:  # pragma: no cover - only without abu_model
    _Base = ValueError  # type: ignore[assignment,misc]

KIND = "abu-profile"
VERSION = 1
INTERPOLATIONS = ("cubic-clamped",)
MAX_KNOTS = 10_000
#: largest speed of a profile [rad/s] (1000 Hz: far beyond any CD drive)
MAX_SPEED = 2.0 * math.pi * 1000.0
UNITS = {"time_s": "s", "omega_rad_s": "rad/s"}
KNOWN = {"kind", "format_version", "interpolation", "time_s", "omega_rad_s", "units", "design",
         "source"}


class ProfileFileError(_Base):  # type: ignore[misc,valid-type]
    """A profile.json is unreadable or invalid; the message names the file and the field."""

    def __init__(self, source: str, message: str, field_name: str | None = None):
        self.source, self.field = source, field_name
        where = source + (f", field '{field_name}'" if field_name else "")
        super().__init__(f"{where}: {message}")


@dataclass(frozen=True)
class Profile:
    """A prescribed speed trajectory (see the module doc).

    Attributes:
        times: knot times [s], strictly increasing (>= 2 knots).
        omegas: knot speeds [rad/s], non-zero, one sign.
        design: informative record of how it was designed (not validated).
        source: where it came from (a path or a description).
    """

    times: tuple[float, ...]
    omegas: tuple[float, ...]
    design: dict | None = None
    source: str = "profile"

    def __post_init__(self) -> None:
        _check_knots(self.source, list(self.times), list(self.omegas))
        object.__setattr__(self, "_coef", _clamped_spline(self.times, self.omegas))

    @property
    def coefficients(self) -> list[tuple[float, float, float, float]]:
        """Per segment k (t_k..t_k+1): (a0, a1, a2, a3), w = a0 + a1 u + a2 u^2 + a3 u^3 with
        u = t - t_k [rad/s, rad/s^2, rad/s^3, rad/s^4]."""
        return list(self._coef)  # type: ignore[attr-defined]

    def evaluate(self, t: float) -> tuple[float, float, float]:
        """(omega_p [rad/s], its rate [rad/s^2], its second derivative [rad/s^3]) at t [s]."""
        ts = self.times
        if t <= ts[0]:
            return self.omegas[0], 0.0, 0.0
        if t >= ts[-1]:
            return self.omegas[-1], 0.0, 0.0
        lo, hi = 0, len(ts) - 1
        while hi - lo > 1:   # bisection: the segment holding t
            mid = (lo + hi) // 2
            if ts[mid] <= t:
                lo = mid
            else:
                hi = mid
        a0, a1, a2, a3 = self._coef[lo]  # type: ignore[attr-defined]
        u = t - ts[lo]
        return (a0 + u * (a1 + u * (a2 + u * a3)), a1 + u * (2 * a2 + 3 * a3 * u),
                2 * a2 + 6 * a3 * u)

    def to_dict(self) -> dict[str, Any]:
        """The JSON object of the file."""
        out: dict[str, Any] = {"kind": KIND, "format_version": VERSION,
                               "interpolation": INTERPOLATIONS[0], "time_s": list(self.times),
                               "omega_rad_s": list(self.omegas), "units": dict(UNITS)}
        if self.design:
            out["design"] = self.design
        out["source"] = self.source
        return out


def _clamped_spline(x: tuple[float, ...], y: tuple[float, ...]
                    ) -> tuple[tuple[float, float, float, float], ...]:
    """Cubic spline through (x, y) with zero end slopes: per-segment power coefficients.

    Unknowns: the second derivatives M_k at the knots; the clamped end conditions and the C2
    conditions form a tridiagonal system (Thomas algorithm)."""
    n = len(x)
    h = [x[k + 1] - x[k] for k in range(n - 1)]
    s = [(y[k + 1] - y[k]) / h[k] for k in range(n - 1)]
    a, b, c, r = [0.0] * n, [0.0] * n, [0.0] * n, [0.0] * n
    b[0], c[0], r[0] = 2 * h[0], h[0], 6 * s[0]                 # s'(x_0) = 0
    for k in range(1, n - 1):
        a[k], b[k], c[k] = h[k - 1], 2 * (h[k - 1] + h[k]), h[k]
        r[k] = 6 * (s[k] - s[k - 1])
    a[n - 1], b[n - 1], r[n - 1] = h[n - 2], 2 * h[n - 2], -6 * s[n - 2]   # s'(x_n) = 0
    for k in range(1, n):       # forward sweep
        f = a[k] / b[k - 1]
        b[k] -= f * c[k - 1]
        r[k] -= f * r[k - 1]
    m = [0.0] * n
    m[n - 1] = r[n - 1] / b[n - 1]
    for k in range(n - 2, -1, -1):
        m[k] = (r[k] - c[k] * m[k + 1]) / b[k]
    return tuple((y[k], s[k] - h[k] * (2 * m[k] + m[k + 1]) / 6.0, m[k] / 2.0,
                  (m[k + 1] - m[k]) / (6.0 * h[k])) for k in range(n - 1))


def _is_num(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _check_knots(source: str, times: list, omegas: list) -> None:
    for name, values in (("time_s", times), ("omega_rad_s", omegas)):
        if not isinstance(values, list) or not 2 <= len(values) <= MAX_KNOTS:
            raise ProfileFileError(source, f"expected a list of 2 to {MAX_KNOTS} numbers, got "
                                           f"{_short(values)}", name)
        for i, v in enumerate(values):
            if not _is_num(v):
                raise ProfileFileError(source, f"item {i}: expected a finite number, got {v!r}",
                                       name)
    if len(times) != len(omegas):
        raise ProfileFileError(source, f"expected as many speeds as times ({len(times)}), got "
                                       f"{len(omegas)}", "omega_rad_s")
    for i in range(1, len(times)):
        if not times[i] > times[i - 1]:
            raise ProfileFileError(source, f"item {i}: expected strictly increasing times, got "
                                           f"{times[i]!r} after {times[i - 1]!r}", "time_s")
    sign = math.copysign(1.0, omegas[0])
    for i, w in enumerate(omegas):
        if w == 0 or math.copysign(1.0, w) != sign or abs(w) > MAX_SPEED:
            raise ProfileFileError(source, f"item {i}: expected a non-zero speed of the sign of "
                                           f"the first, |w| <= {MAX_SPEED:.6g} rad/s, got {w!r}",
                                   "omega_rad_s")


def _short(v: Any) -> str:
    text = repr(v)
    return text if len(text) <= 60 else text[:57] + "..."


def profile_from_dict(obj: Any, source: str = "profile.json") -> Profile:
    """Validate a parsed profile.json object; :class:`ProfileFileError` names the field."""
    if not isinstance(obj, dict):
        raise ProfileFileError(source, "expected a JSON object")
    if obj.get("kind") != KIND:
        raise ProfileFileError(source, f"expected {KIND!r} (a profile written by 'abu design'), "
                                       f"got {obj.get('kind')!r}", "kind")
    version = obj.get("format_version")
    if isinstance(version, bool) or version != VERSION:
        raise ProfileFileError(source, f"expected {VERSION}, got {version!r}", "format_version")
    interp = obj.get("interpolation", INTERPOLATIONS[0])
    if interp not in INTERPOLATIONS:
        raise ProfileFileError(source, f"expected one of {', '.join(INTERPOLATIONS)}, got "
                                       f"{interp!r}", "interpolation")
    for name in ("time_s", "omega_rad_s"):
        if name not in obj:
            raise ProfileFileError(source, "missing", name)
    unknown = sorted(set(obj) - KNOWN)
    if unknown:
        raise ProfileFileError(source, f"not a field of a profile (known: "
                                       f"{', '.join(sorted(KNOWN))})", unknown[0])
    _check_knots(source, obj["time_s"], obj["omega_rad_s"])
    design = obj.get("design")
    return Profile(tuple(float(v) for v in obj["time_s"]),
                   tuple(float(v) for v in obj["omega_rad_s"]),
                   design if isinstance(design, dict) else None, source)


def load_profile(path: str | Path) -> Profile:
    """Read and validate a profile.json; :class:`ProfileFileError` names the file and field."""
    obj, source = read_json_object(path, "a JSON object (a profile.json of 'abu design')",
                                   ProfileFileError)
    return profile_from_dict(obj, source)


def dumps_profile(profile: Profile) -> str:
    """Strict JSON text of a profile."""
    return json.dumps(profile.to_dict(), indent=2, allow_nan=False) + "\n"


__all__ = ["Profile", "ProfileFileError", "load_profile", "profile_from_dict", "dumps_profile",
           "KIND", "VERSION"]
