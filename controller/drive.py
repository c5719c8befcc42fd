"""The ``drive.json`` schema: an identified closed speed loop of the setup (stdlib only).

``abu identify`` writes it; ``abu simulate``, ``abu render``, ``abu design``, ``abu next`` and
``abu measure`` read it with ``--drive drive.json``. This module imports nothing outside the
standard library (it may be vendored into an FMU), except the shared error type when present.

The file is one JSON object (SI units, the unit in each key)::

    {"kind": "abu-drive", "format_version": 1,
     "model": "second-order" | "pi-lag" | "pi-lag-weighted" | "tracking",
     "theta_ref_mode": "integral",
     "zeta": 0.7, "omega_n_rad_s": 12.0, "tau_motor_s": 0.02, "setpoint_weight": 1.0,
     "zeta_ci95": [lo, hi], "omega_n_rad_s_ci95": [lo, hi], ...   (optional)
     "fit": {...}, "units": {...}, "source": "..."}                  (optional, informative)

The loop is the PI law on the rotor (report eq. 4.5 read as a PI law, ``integral`` reading)
with a first-order lag tau_motor between commanded and applied torque and a setpoint weight b
on the proportional part:

    T_cmd = Kp (b w_ref - w) + Ki integral(w_ref - w),  Kp = 2 zeta wn J,  Ki = wn^2 J,
    tau_motor T' = T_cmd - T,  J w' = T,
    w / w_ref = (2 zeta wn b s + wn^2) / (tau_motor s^3 + s^2 + 2 zeta wn s + wn^2).

``second-order`` has tau_motor = 0 and b = 1 (the report's model), ``pi-lag`` b = 1.

Two optional fields of the PI models describe a drive more closely (absent: as above):

* ``setpoint_tau_s`` [s] (> 0; ``setpoint_tau_s_ci95`` optional): a first-order setpoint
  filter, w_f / w_ref = 1 / (setpoint_tau s + 1), before the loop (w_ref -> w_f above).
* ``sample_time_s`` [s] (> 0): the controller is digital with this sample time and generates
  the staircase on its own clock, so each step acts at the first sample k * sample_time at or
  after the step's time. (Its integrator's discretisation is not modelled: a forward-Euler one
  shifts the loop's zeta by about omega_n sample_time / 4, absorbed by the identified zeta.)

Only ``abu measure --kinematics drive-model`` and the design's loop response use them;
``abu simulate`` and ``abu render`` refuse a drive that has them (their controller has neither).

``tracking`` is the drive the report's chapter 6 recommends: a loop that follows a prescribed
smooth speed trajectory omega_p(t) (``profile.json``, :mod:`controller.profile`) with a known
bandwidth wb [rad/s] (``bandwidth_rad_s``, required; ``bandwidth_rad_s_ci95`` optional) and the
same torque lag (``tau_motor_s``, default 0)::

    T_cmd = J wb (w_p - w),  tau_motor T' = T_cmd - T,  J w' = T,
    w / w_p = wb / (tau_motor s^2 + s + wb)      (tau_motor = 0: first order, -3 dB at wb)

``zeta``, ``omega_n_rad_s`` and ``setpoint_weight`` are not fields of a tracking drive (refused
by name), nor ``bandwidth_rad_s`` of the PI models.

Checked on load, each refusal naming the file and the field: every number finite and within
its field's range (:data:`UPPER`; > 0 but for :data:`MAY_BE_ZERO`), every ``*_ci95`` a pair
low <= high within that same range; an optional field given as ``null`` is absent; a PI loop
must be stable: tau_motor < 2 zeta / omega_n (Routh-Hurwitz on its characteristic polynomial
above).
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from controller.json_file import read_json_object

try:  # the shared error type; without abu_model it falls back to ValueError
    from abu_model.errors import AbuError as _Base
except ImportError:  # pragma: no cover - only without abu_model
    _Base = ValueError  # type: ignore[assignment,misc]

KIND = "abu-drive"
VERSION = 1
MODELS = ("second-order", "pi-lag", "pi-lag-weighted", "tracking")
PI_MODELS = MODELS[:3]
#: Fitted parameters of each model (names as in the file).
MODEL_PARAMETERS: dict[str, tuple[str, ...]] = {
    "second-order": ("zeta", "omega_n_rad_s"),
    "pi-lag": ("zeta", "omega_n_rad_s", "tau_motor_s"),
    "pi-lag-weighted": ("zeta", "omega_n_rad_s", "tau_motor_s", "setpoint_weight"),
    "tracking": ("bandwidth_rad_s", "tau_motor_s"),
}
UNITS = {"zeta": "1", "omega_n_rad_s": "rad/s", "tau_motor_s": "s", "setpoint_weight": "1",
         "bandwidth_rad_s": "rad/s", "setpoint_tau_s": "s", "sample_time_s": "s"}
#: Optional fields of the PI models (module doc); absent = no setpoint filter, continuous.
PI_OPTIONAL = ("setpoint_tau_s", "sample_time_s")
#: Fields of a PI drive that a tracking drive must not carry, and the reverse.
PI_ONLY = ("zeta", "omega_n_rad_s", "setpoint_weight") + PI_OPTIONAL
TRACKING_ONLY = ("bandwidth_rad_s",)


class DriveFileError(_Base):  # type: ignore[misc,valid-type]
    """A drive.json is unreadable or invalid; the message names the file and the field."""

    def __init__(self, source: str, message: str, field_name: str | None = None):
        self.source, self.field = source, field_name
        where = source + (f", field '{field_name}'" if field_name else "")
        super().__init__(f"{where}: {message}")


@dataclass(frozen=True)
class Drive:
    """An identified speed loop (SI).

    Attributes:
        model: one of :data:`MODELS`.
        zeta: damping ratio of the PI loop [-] (> 0).
        omega_n: natural frequency of the PI loop [rad/s] (> 0).
        tau_motor: torque lag [s] (>= 0; 0 for ``second-order``).
        setpoint_weight: b, weight of the setpoint in the proportional part [-] (> 0).
        bandwidth: ``tracking`` only: the loop's bandwidth wb [rad/s] (> 0; None otherwise).
        setpoint_tau: PI models: time constant of a first-order setpoint filter [s] (0: none).
        sample_time: PI models: the digital controller's sample time [s] (None: continuous).
        ci95: parameter name (file name, e.g. ``omega_n_rad_s``) -> (low, high) 95 % interval.
        fit: informative fit data (residual check, sizes); not validated.
        source: where the drive came from (a path or a description).
    """

    model: str = "second-order"
    zeta: float = 0.5
    omega_n: float = 2.2
    tau_motor: float = 0.0
    setpoint_weight: float = 1.0
    bandwidth: float | None = None
    setpoint_tau: float = 0.0
    sample_time: float | None = None
    ci95: dict[str, tuple[float, float]] = field(default_factory=dict)
    fit: dict[str, Any] = field(default_factory=dict)
    source: str = "default"

    def __post_init__(self) -> None:
        src = self.source
        if self.model not in MODELS:
            raise DriveFileError(src, f"expected one of {', '.join(MODELS)}, got {self.model!r}",
                                 "model")
        for name, value, low in (("zeta", self.zeta, 0.0), ("omega_n_rad_s", self.omega_n, 0.0),
                                 ("setpoint_weight", self.setpoint_weight, 0.0)):
            _check_number(src, name, value, low, strict=True)
        _check_number(src, "tau_motor_s", self.tau_motor, 0.0, strict=False)
        if self.model == "second-order" and self.tau_motor != 0.0:
            raise DriveFileError(src, "must be 0 for the second-order model", "tau_motor_s")
        if self.model != "pi-lag-weighted" and self.setpoint_weight != 1.0:
            raise DriveFileError(src, f"must be 1 for the {self.model} model", "setpoint_weight")
        _check_number(src, "setpoint_tau_s", self.setpoint_tau, 0.0, strict=False)
        if self.sample_time is not None:
            _check_number(src, "sample_time_s", self.sample_time, 0.0, strict=True)
        if self.model == "tracking":
            _check_number(src, "bandwidth_rad_s", self.bandwidth, 0.0, strict=True)
            for name, absent in (("setpoint_tau_s", not self.has_setpoint_filter),
                                 ("sample_time_s", self.sample_time is None)):
                if not absent:
                    raise DriveFileError(src, "not a parameter of the tracking model", name)
        elif self.bandwidth is not None:
            raise DriveFileError(src, f"not a parameter of the {self.model} model (only of "
                                 "'tracking')", "bandwidth_rad_s")

    @property
    def is_tracking(self) -> bool:
        """A drive that tracks a prescribed profile (``profile.json``), not a staircase."""
        return self.model == "tracking"

    @property
    def is_stable(self) -> bool:
        """The loop is stable: a tracking loop always; a PI loop below :func:`lag_limit_s`."""
        return self.model == "tracking" or self.tau_motor < lag_limit_s(self.zeta, self.omega_n)

    @property
    def has_setpoint_filter(self) -> bool:
        """A setpoint filter is declared: ``setpoint_tau_s`` > 0 or its interval alone (the
        drive model then fits it from the interval's middle)."""
        return self.setpoint_tau > 0.0 or "setpoint_tau_s" in self.ci95

    @property
    def theta_ref_mode(self) -> str:
        """The PI reading of the drive (always the physical ``integral`` one)."""
        return "integral"

    def value(self, name: str) -> float:
        """Parameter by its file name (``zeta``, ``omega_n_rad_s``, ...)."""
        return {"zeta": self.zeta, "omega_n_rad_s": self.omega_n, "tau_motor_s": self.tau_motor,
                "setpoint_weight": self.setpoint_weight, "bandwidth_rad_s": self.bandwidth,
                "setpoint_tau_s": self.setpoint_tau, "sample_time_s": self.sample_time}[name]

    def to_dict(self) -> dict[str, Any]:
        """The JSON object of the file (see the module docstring)."""
        out: dict[str, Any] = {"kind": KIND, "format_version": VERSION, "model": self.model}
        if self.is_tracking:
            out.update(bandwidth_rad_s=self.bandwidth, tau_motor_s=self.tau_motor)
        else:
            out.update(theta_ref_mode=self.theta_ref_mode, zeta=self.zeta,
                       omega_n_rad_s=self.omega_n, tau_motor_s=self.tau_motor,
                       setpoint_weight=self.setpoint_weight)
            if self.setpoint_tau > 0:
                out["setpoint_tau_s"] = self.setpoint_tau
            if self.sample_time is not None:
                out["sample_time_s"] = self.sample_time
        for name, (lo, hi) in self.ci95.items():
            out[f"{name}_ci95"] = [lo, hi]
        out["units"] = {k: v for k, v in UNITS.items() if k in out}
        if self.fit:
            out["fit"] = self.fit
        out["source"] = self.source
        return out


#: Largest plausible value of each parameter (zeta [-], omega_n [rad/s], tau_motor [s], b [-]):
#: a damping ratio, the natural frequency of a CD drive's speed loop, a motor's torque lag.
UPPER = {"zeta": 1000.0, "omega_n_rad_s": 1.0e4, "tau_motor_s": 1.0, "setpoint_weight": 100.0,
         "bandwidth_rad_s": 1.0e5, "setpoint_tau_s": 1.0, "sample_time_s": 1.0}
#: Fields that may be 0 (no lag, no setpoint filter); every other one must be > 0.
MAY_BE_ZERO = ("tau_motor_s", "setpoint_tau_s")


def _check_number(source: str, name: str, value: Any, low: float, strict: bool) -> float:
    high = UPPER.get(name, math.inf)
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or not math.isfinite(float(value)) or (value <= low if strict else value < low) \
            or value > high:
        raise DriveFileError(source, f"expected a finite number {'>' if strict else '>='} {low:g}"
                                     + (f" and <= {high:g}" if math.isfinite(high) else "")
                                     + f", got {value!r}", name)
    return float(value)


def _given(obj: dict, name: str, default: Any) -> Any:
    """``obj[name]``, or ``default`` when the field is absent or null."""
    value = obj.get(name)
    return default if value is None else value


def lag_limit_s(zeta: float, omega_n: float) -> float:
    """The torque lag [s] from which a PI loop is unstable: the Routh-Hurwitz limit of its
    characteristic polynomial tau s^3 + s^2 + 2 zeta omega_n s + omega_n^2 is tau < 2 zeta /
    omega_n. A drive identified from a record was stable while recorded; beyond the limit
    its speed oscillates ever more and every plan and kinematic model built on it is void."""
    return 2.0 * zeta / omega_n


def _check_stable(source: str, zeta: float, omega_n: float, tau_motor: float) -> None:
    """DriveFileError naming ``tau_motor_s`` at or beyond :func:`lag_limit_s`."""
    limit = lag_limit_s(zeta, omega_n)
    if tau_motor >= limit:
        raise DriveFileError(source, f"a torque lag below 2 zeta / omega_n = {limit:.4g} s, got "
                                     f"{tau_motor:g} s: with it the loop tau s^3 + s^2 + 2 zeta "
                                     "omega_n s + omega_n^2 is unstable (Routh-Hurwitz), which "
                                     "no drive identified from a record is", "tau_motor_s")


def drive_from_dict(obj: Any, source: str = "drive.json") -> Drive:
    """Validate a parsed drive.json object; raises :class:`DriveFileError` naming the field."""
    if not isinstance(obj, dict):
        raise DriveFileError(source, "expected a JSON object")
    if obj.get("kind") != KIND:
        raise DriveFileError(source, f"expected {KIND!r} (a drive written by 'abu identify'), "
                                     f"got {obj.get('kind')!r}", "kind")
    # ``format_version`` (older files: ``version``)
    key = "format_version" if "format_version" in obj else "version"
    version = obj.get(key)
    if isinstance(version, bool) or version != VERSION:
        raise DriveFileError(source, f"expected {key} {VERSION}, got {version!r}", key)
    model = obj.get("model")
    if model not in MODELS:
        raise DriveFileError(source, f"expected one of {', '.join(MODELS)}, got {model!r}",
                             "model")
    if model == "tracking":
        return _tracking_from_dict(obj, source)
    if "bandwidth_rad_s" in obj:
        raise DriveFileError(source, f"not a parameter of the {model} model (only of "
                                     "'tracking')", "bandwidth_rad_s")
    mode = obj.get("theta_ref_mode", "integral")
    if mode != "integral":
        raise DriveFileError(source, f"expected 'integral', got {mode!r}", "theta_ref_mode")
    for name in ("zeta", "omega_n_rad_s"):
        if name not in obj:
            raise DriveFileError(source, "missing", name)
    # an optional field given as null is absent (as sample_time_s always was)
    values = {name: _given(obj, name, default) for name, default in
              (("zeta", None), ("omega_n_rad_s", None), ("tau_motor_s", 0.0),
               ("setpoint_weight", 1.0))}
    for name, value in values.items():
        _check_number(source, name, value, 0.0, strict=name not in MAY_BE_ZERO)
    _check_stable(source, float(values["zeta"]), float(values["omega_n_rad_s"]),
                  float(values["tau_motor_s"]))
    tau_f = _check_number(source, "setpoint_tau_s", _given(obj, "setpoint_tau_s", 0.0), 0.0,
                          strict=False)
    sample = obj.get("sample_time_s")
    if sample is not None:
        sample = _check_number(source, "sample_time_s", sample, 0.0, strict=True)
    ci95 = _intervals(obj, model, source)
    fit = obj.get("fit") or {}
    return Drive(model=model, zeta=float(values["zeta"]),
                 omega_n=float(values["omega_n_rad_s"]), tau_motor=float(values["tau_motor_s"]),
                 setpoint_weight=float(values["setpoint_weight"]), setpoint_tau=tau_f,
                 sample_time=sample, ci95=ci95, fit=fit if isinstance(fit, dict) else {},
                 source=source)


def _intervals(obj: dict, model: str, source: str) -> dict[str, tuple[float, float]]:
    """The ``<name>_ci95`` pairs of the model's parameters (checked when present)."""
    ci95: dict[str, tuple[float, float]] = {}
    extra = ("setpoint_tau_s",) if model in PI_MODELS else ()
    for name in MODEL_PARAMETERS[model] + extra:
        key = f"{name}_ci95"
        if key in obj and obj[key] is not None:
            pair = obj[key]
            if (not isinstance(pair, list) or len(pair) != 2
                    or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                               and math.isfinite(v) for v in pair) or pair[0] > pair[1]):
                raise DriveFileError(source, f"expected [low, high] with low <= high, got {pair!r}",
                                     key)
            zero_ok = name in MAY_BE_ZERO
            if (pair[0] < 0.0 if zero_ok else pair[0] <= 0.0) or pair[1] > UPPER[name]:
                # a design takes its corners and the drive model its middle as a prior: within
                # the field's own range
                raise DriveFileError(source, f"expected 0 {'<=' if zero_ok else '<'} low <= high "
                                             f"<= {UPPER[name]:g}, got {pair!r}", key)
            ci95[name] = (float(pair[0]), float(pair[1]))
    return ci95


def _tracking_from_dict(obj: dict, source: str) -> Drive:
    """A ``tracking`` drive: bandwidth required, tau_motor optional, no PI fields."""
    for name in PI_ONLY + tuple(f"{n}_ci95" for n in PI_ONLY) + ("theta_ref_mode",):
        if name in obj:
            raise DriveFileError(source, "not a parameter of the tracking model (its loop is "
                                         "bandwidth_rad_s and tau_motor_s)", name)
    if "bandwidth_rad_s" not in obj:
        raise DriveFileError(source, "missing (the tracking loop's bandwidth [rad/s])",
                             "bandwidth_rad_s")
    wb = _check_number(source, "bandwidth_rad_s", obj["bandwidth_rad_s"], 0.0, strict=True)
    tau = _check_number(source, "tau_motor_s", _given(obj, "tau_motor_s", 0.0), 0.0,
                        strict=False)
    ci95 = _intervals(obj, "tracking", source)
    fit = obj.get("fit") or {}
    return Drive(model="tracking", tau_motor=tau, bandwidth=wb, ci95=ci95,
                 fit=fit if isinstance(fit, dict) else {}, source=source)


def load_drive(path: str | Path) -> Drive:
    """Read and validate a drive.json; :class:`DriveFileError` names the file and the field."""
    obj, source = read_json_object(path, "a JSON object (a drive.json of 'abu identify')",
                                   DriveFileError)
    return drive_from_dict(obj, source)


def dumps_drive(drive: Drive) -> str:
    """Strict JSON text of a drive (what ``abu identify`` writes)."""
    return json.dumps(drive.to_dict(), indent=2, allow_nan=False) + "\n"
