"""``abu design`` for a ``tracking`` drive: the prescribed speed profile for a prior range of mu.

Physics (ball stuck): mu_req(t) = q(t) = (l - d/5) |alpha| / (l omega^2). Prescribing q(t)
fixes the speed in closed form: with lever = (l - d/5)/l and the drive accelerating away from
zero, d(1/|omega|)/dt = -q(t) / lever, so

    1 / |omega(t)| = 1 / |omega_e| + (Q(t_e) - Q(t)) / lever,   Q = integral of q.

(braking instead, ``sweep = decelerate``, the default: 1/|omega(t)| = 1/|omega_s| + Q(t)/lever).
The profile (``profile.json``, :mod:`controller.profile`) holds the start speed, raises q
smoothly from 0 to ``mu_lo / margin`` (``ramp_in_s``), sweeps it linearly through the prior
range to ``mu_hi * margin`` at the rate ``sweep_rate`` [1/s] (steep but continuous: no
acceleration steps), then lowers it smoothly to 0 (``ramp_out_s``) and holds the end speed.
The speed at the crossing matters most: the kinematic part of the width falls as
1/omega^2 at a fixed sweep rate. The speed cannot stay high during a slow sweep (the formula
above), so the design trades the sweep rate against the speeds it forces, within the
camera's limits: the record length (the whole sweep inside it, ``edge_s`` from both ends),
frames (rotation per frame), motion blur (the ball's travel during the exposure), and the
drive's acceleration limit. The profile's knots are the designed speed sampled every
``knot_spacing_s``; the design then evaluates the profile *through the drive's loop*
(:mod:`abu_model.tracking_response`, exact) for the predicted slip times and mu_req.

Width prediction (per mu of the prior range, the slip at q = mu at speed omega and sweep rate
q' there): the slip emerges from beta's noise sigma_beta after tau_d with
omega^2 / 1.4 * (q' tau^3 / 6 + (mu - mu_d) tau^2 / 2) = k sigma_beta (mu_d = mu: cubic, the
slowest), so the onset is located to ~q' tau_d in q; the kinematic error of mu_req at the slip
is ``kin_rel`` relative (the drive model's floor). Relative width ~ sqrt((q' tau_d)^2 +
(2 z kin_rel mu)^2) / mu. The constants (sigma_beta, k, kin_rel) are calibrated on rendered runs
(``benchmarks/bench_profile_drive.py`` prints predicted and measured widths): with
kin_rel = the measurement's 1 % floor and mu_d = 0.8 mu, sigma_beta k = 3e-3 rad puts the
measured / predicted width of seeds 100-129 at a median 0.92 (10-90 % 0.87-1.32).
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace

import numpy as np

from abu_model.errors import ParameterError
from abu_model.params import BallParams
from abu_model.tracking_response import response
from controller.drive import Drive
from controller.profile import Profile

TWO_PI = 2.0 * math.pi
SWEEPS = ("decelerate", "accelerate")


@dataclass(frozen=True)
class ProfileDesignSpec:
    """What a profile design needs (SI; speeds in rad/s).

    Attributes:
        mu_lo, mu_hi: prior range of mu [-].
        drive: a ``tracking`` drive (its bandwidth and lag).
        ball: ball geometry (l, d).
        fps, n_frames: the camera [frames/s, -]; the record is [0, (n_frames - 1) / fps].
        speed_max: camera/drive speed cap [rad/s] (rotation per frame, blur).
        speed_min: slowest speed at the start of the sweep [rad/s].
        alpha_max: the drive's largest acceleration [rad/s^2].
        blur_px_max, exposure_fraction, pixel_size: the ball's travel during the exposure
            must stay <= blur_px_max [px] at exposure_fraction / fps [s] and pixel_size [m/px].
        margin: the sweep runs from mu_lo / margin to mu_hi * margin [-].
        edge_s: the sweep starts and ends at least this far inside the record [s].
        ramp_in_s, ramp_out_s: smooth rise of q from 0, fall back to 0 [s].
        knot_spacing_s: profile knots [s].
        sigma_beta, k_sigma, kin_rel, mu_d_ratio: width predictor (see the module doc and
            :func:`predict_width`) [rad, -, -, -]; calibrated on bench_profile_drive.py.
        direction: -1 (clockwise, the report's sign) or +1.
        sweep: ``decelerate`` (default: start at the speed cap and brake, so the low mu of
            the range slip at the highest speed, where their relative width needs it most)
            or ``accelerate`` (end at the cap).
    """

    mu_lo: float
    mu_hi: float
    drive: Drive
    ball: BallParams = field(default_factory=BallParams)
    fps: float = 4500.0
    n_frames: int = 3072
    speed_max: float = 40.0 * TWO_PI
    speed_min: float = 3.0 * TWO_PI
    alpha_max: float = 5000.0
    blur_px_max: float = 1.5
    exposure_fraction: float = 0.5
    pixel_size: float = 0.3e-3
    margin: float = 1.15
    edge_s: float = 0.05
    ramp_in_s: float = 0.04
    ramp_out_s: float = 0.04
    knot_spacing_s: float = 0.005
    sigma_beta: float = 1.0e-3
    k_sigma: float = 3.0
    kin_rel: float = 0.01
    mu_d_ratio: float = 0.8
    direction: int = -1
    sweep: str = "decelerate"

    def __post_init__(self) -> None:
        if not (0 < self.mu_lo < self.mu_hi < 1):
            raise ParameterError("--mu-range", (self.mu_lo, self.mu_hi),
                                 "0 < LO < HI < 1 (static friction coefficients)")
        if not self.drive.is_tracking:
            raise ParameterError("--drive", self.drive.source, "a drive of model 'tracking'")
        if self.sweep not in SWEEPS:
            raise ParameterError("--sweep", self.sweep, " or ".join(SWEEPS))
        if self.direction not in (-1, 1):
            raise ParameterError("direction", self.direction, "-1 or +1")
        for name in ("fps", "speed_max", "speed_min", "alpha_max", "blur_px_max",
                     "exposure_fraction", "pixel_size", "knot_spacing_s", "ramp_in_s",
                     "ramp_out_s", "sigma_beta", "k_sigma"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ParameterError(name, v, "a finite number > 0")
        if self.speed_min >= self.speed_max:
            raise ParameterError("--speed-min-hz", self.speed_min / TWO_PI,
                                 "a speed below --speed-max-hz")

    @property
    def lever(self) -> float:
        return self.ball.lever_ratio

    @property
    def record_s(self) -> float:
        return (self.n_frames - 1) / self.fps

    def speed_cap(self) -> float:
        """The fastest speed the camera and the set-up allow [rad/s]: speed_max, and the ball's
        blur (l |omega| exposure / fps <= blur_px_max pixels)."""
        blur = self.blur_px_max * self.pixel_size * self.fps / (self.ball.l
                                                                 * self.exposure_fraction)
        return min(self.speed_max, blur)


def _smoothstep_integral(u: np.ndarray) -> np.ndarray:
    """Integral over [0, u] of 3 s^2 - 2 s^3 (u clipped to [0, 1])."""
    u = np.clip(u, 0.0, 1.0)
    return u**3 - 0.5 * u**4


def q_profile(spec: ProfileDesignSpec, rate: float, t_start: float
              ) -> tuple[np.ndarray, np.ndarray, dict]:
    """q(t) and Q(t) = its integral on a fine grid over the record, and the phase times.

    Phases: 0 until t_start; smoothstep rise to q0 over ramp_in_s; linear q0 -> q1 at ``rate``
    [1/s]; smoothstep fall to 0 over ramp_out_s."""
    q0, q1 = spec.mu_lo / spec.margin, spec.mu_hi * spec.margin
    t1 = t_start + spec.ramp_in_s
    t2 = t1 + (q1 - q0) / rate
    t3 = t2 + spec.ramp_out_s
    t = np.linspace(0.0, spec.record_s, 4001)
    u_in = np.clip((t - t_start) / spec.ramp_in_s, 0, 1)
    u_out = np.clip((t - t2) / spec.ramp_out_s, 0, 1)
    s_in = u_in * u_in * (3 - 2 * u_in)
    s_out = u_out * u_out * (3 - 2 * u_out)
    lin = np.clip(t - t1, 0.0, t2 - t1)
    q = np.where(t < t1, q0 * s_in, np.where(t <= t2, q0 + rate * lin, q1 * (1 - s_out)))
    Q = (q0 * spec.ramp_in_s * _smoothstep_integral(u_in)
         + q0 * lin + 0.5 * rate * lin**2
         + q1 * spec.ramp_out_s * (u_out - _smoothstep_integral(u_out)))
    return t, np.vstack([q, Q]), {"t_start_s": t_start, "t_sweep_start_s": t1,
                                  "t_sweep_end_s": t2, "t_end_s": t3, "q0": q0, "q1": q1}


def speed_curve(spec: ProfileDesignSpec, Q: np.ndarray, speed_cap: float) -> np.ndarray:
    """|omega(t)| [rad/s] for the integral Q(t) of q: braking from ``speed_cap``
    (``decelerate``: 1/|w| = 1/cap + Q/lever) or accelerating to it (``accelerate``:
    1/|w| = 1/cap + (Q_end - Q)/lever)."""
    if spec.sweep == "decelerate":
        return 1.0 / (1.0 / speed_cap + Q / spec.lever)
    return 1.0 / (1.0 / speed_cap + (Q[-1] - Q) / spec.lever)


def make_profile(spec: ProfileDesignSpec, rate: float, t_start: float, speed_cap: float
                 ) -> tuple[Profile, dict]:
    """The profile of sweep rate ``rate`` [1/s] starting at ``t_start`` [s] whose fastest
    speed is ``speed_cap`` [rad/s] (at the start when braking, at the end when accelerating;
    see the module doc)."""
    t, (q, Q), phases = q_profile(spec, rate, t_start)
    speed = speed_curve(spec, Q, speed_cap)
    n = max(2, int(math.ceil((phases["t_end_s"] - t_start) / spec.knot_spacing_s)) + 1)
    tk = np.linspace(t_start, phases["t_end_s"], n)
    wk = spec.direction * np.interp(tk, t, speed)
    profile = Profile(tuple(float(v) for v in tk), tuple(float(v) for v in wk),
                      source="abu design")
    return profile, {**phases, "sweep": spec.sweep, "speed_start_rad_s": float(speed[0]),
                     "speed_end_rad_s": float(speed[-1])}


def crossing(spec: ProfileDesignSpec, profile: Profile, mus: np.ndarray
             ) -> dict[str, np.ndarray]:
    """Through the drive's loop (exact): for each mu the first time mu_req(t) >= mu, the speed,
    mu_req's rate there, and the whole mu_req curve on the frame grid."""
    t = np.arange(spec.n_frames) / spec.fps
    d = spec.drive
    r = response(profile, t, float(d.bandwidth), d.tau_motor)
    q = spec.lever * np.abs(r.alpha) / np.maximum(r.omega**2, 1e-300)
    run = np.maximum.accumulate(q)
    idx = np.searchsorted(run, mus, side="left")
    ok = idx < t.size
    i = np.minimum(idx, t.size - 1)
    dq = np.gradient(q, t)
    return {"t": t, "q": q, "omega": r.omega, "alpha": r.alpha, "index": i, "reached": ok,
            "t_slip": np.where(ok, t[i], np.nan), "speed": np.abs(r.omega[i]),
            "rate": np.maximum(dq[i], 1e-9)}


def predict_width(spec: ProfileDesignSpec, mu: np.ndarray, speed: np.ndarray,
                  rate: np.ndarray) -> np.ndarray:
    """Predicted relative width [-] at each mu (slip at |omega| = speed, q' = rate).

    The onset emerges after tau with omega^2 / 1.4 (q' tau^3 / 6 + (mu - mu_d) tau^2 / 2)
    = k sigma_beta (mu_d = mu_d_ratio mu: the cubic and the quadratic term), located to
    q' tau in q; the kinematics add +- z kin_rel mu."""
    mu = np.asarray(mu, float)
    a = speed**2 * rate / (6.0 * 1.4)
    b = speed**2 * (1.0 - spec.mu_d_ratio) * mu / (2.0 * 1.4)
    c = spec.k_sigma * spec.sigma_beta
    tau = np.cbrt(c / a)
    if np.any(b > 0):
        tau = np.minimum(tau, np.sqrt(c / np.maximum(b, 1e-300)))
    for _ in range(30):   # Newton on the convex increasing a t^3 + b t^2 - c, from the right
        tau = tau - (a * tau**3 + b * tau**2 - c) / (3 * a * tau**2 + 2 * b * tau)
    emerge = rate * tau
    kin = 2.0 * 1.96 * spec.kin_rel * mu
    return np.hypot(emerge, kin) / mu


def _feasible(spec: ProfileDesignSpec, rate: float) -> tuple[float, float, str]:
    """(t_start, fastest speed, '') of a sweep at ``rate`` as fast as the camera and the
    drive's acceleration allow, or (nan, nan, reason)."""
    t, (q, Q), ph = q_profile(spec, rate, 0.0)
    dur = ph["t_end_s"]
    if dur > spec.record_s - 2 * spec.edge_s:
        return math.nan, math.nan, f"the sweep takes {dur:.3g} s, the record {spec.record_s:.3g} s"
    cap = spec.speed_cap()
    for _ in range(8):   # lower the speed until alpha = q w^2 / lever <= alpha_max everywhere
        speed = speed_curve(spec, Q, cap)
        peak = float(np.max(q * speed**2)) / spec.lever
        if peak <= spec.alpha_max * 1.0001:
            break
        cap *= math.sqrt(spec.alpha_max / peak)
    slowest = float(speed.min())
    if slowest < spec.speed_min:
        return math.nan, math.nan, (f"the speed would fall to {slowest / TWO_PI:.3g} Hz (< "
                                    f"{spec.speed_min / TWO_PI:.3g} Hz)")
    t_start = max(spec.edge_s, 0.5 * (spec.record_s - dur))   # centred in the record
    return t_start, cap, ""


@dataclass
class ProfileDesign:
    """Result of :func:`design_profile`."""

    spec: ProfileDesignSpec
    profile: Profile
    rate: float
    phases: dict
    mus: np.ndarray
    t_slip: np.ndarray
    speed: np.ndarray
    width: np.ndarray
    candidates: list[dict]
    width_upper: np.ndarray | None = None

    def upper(self) -> np.ndarray:
        """The width predicted with mu_d = mu (the slowest, cubic onset) [-]: an upper end
        (measured <= it in 27 of 30 unseen benchmark runs, 97 % on the calibration seeds)."""
        spec = replace(self.spec, mu_d_ratio=1.0)
        c = crossing(spec, self.profile, self.mus)
        return predict_width(spec, self.mus, c["speed"], c["rate"])

    def summary(self) -> dict:
        """JSON-ready record (the design's ``summary.json``)."""
        s = self.spec
        return {"kind": "abu-design-profile", "format_version": 1,
                "mu_range": [s.mu_lo, s.mu_hi], "drive": s.drive.to_dict(),
                "sweep_rate_per_s": self.rate, **self.phases,
                "speed_cap_rad_s": s.speed_cap(),
                "predicted": [{"mu": float(m), "t_slip_s": float(t), "speed_rad_s": float(w),
                               "relative_width": float(x), "relative_width_upper": float(u)}
                              for m, t, w, x, u in zip(self.mus, self.t_slip, self.speed,
                                                       self.width, self.upper())],
                "predicted_median_width": float(np.median(self.width)),
                "predicted_upper_width": float(np.max(self.upper())),
                "candidates": self.candidates,
                "settings": {k: v for k, v in asdict(s).items() if k not in ("drive", "ball")},
                "units": {"sweep_rate_per_s": "1/s", "t_slip_s": "s", "speed_rad_s": "rad/s",
                          "speed_cap_rad_s": "rad/s", "relative_width": "1"}}


def design_profile(spec: ProfileDesignSpec, rates: np.ndarray | None = None) -> ProfileDesign:
    """Choose the sweep rate (a grid, geometric) that minimises the largest predicted width
    over the prior range among the feasible ones; raises ParameterError when none fits."""
    span = spec.mu_hi * spec.margin - spec.mu_lo / spec.margin
    grid = rates if rates is not None else span / np.geomspace(0.6, 0.02, 24)
    mus = np.linspace(spec.mu_lo, spec.mu_hi, 9)
    best, cands, reasons = None, [], []
    for rate in grid:
        t_start, cap, why = _feasible(spec, float(rate))
        if why:
            reasons.append(why)
            continue
        profile, phases = make_profile(spec, float(rate), t_start, cap)
        c = crossing(spec, profile, mus)
        if not np.all(c["reached"]):
            reasons.append("the loop does not reach mu_hi")
            continue
        width = predict_width(spec, mus, c["speed"], c["rate"])
        cands.append({"sweep_rate_per_s": float(rate), "worst_width": float(width.max()),
                      "median_width": float(np.median(width))})
        if best is None or width.max() < best[0]:
            best = (float(width.max()), float(rate), profile, phases, c, width)
    if best is None:
        raise ParameterError("--mu-range", (spec.mu_lo, spec.mu_hi),
                             "a range a profile can sweep within the camera's limits ("
                             + (reasons[-1] if reasons else "no candidate") + ")")
    _, rate, profile, phases, c, width = best
    profile = Profile(profile.times, profile.omegas, design={
        "mu_range": [spec.mu_lo, spec.mu_hi], "sweep_rate_per_s": rate, **phases},
        source="abu design")
    return ProfileDesign(spec, profile, rate, phases, mus, c["t_slip"], c["speed"], width, cands)


__all__ = ["ProfileDesignSpec", "ProfileDesign", "design_profile", "make_profile", "crossing",
           "predict_width"]
