"""Digital twin of the report's experiment (sec. 5.3): co-simulate, then film it.

:func:`render_twin` runs the staircase experiment as an FMI co-simulation
(:func:`harness.experiments.staircase.run_staircase`) with a known mu, samples the true state at every
frame time, maps theta and beta to marker positions (:class:`render.CameraGeometry`) and renders
the high-speed camera recording (:func:`render.render_frames`). It writes, atomically:

* ``frames.tif``: multi-page 8-bit TIFF (N frames of H x W), the frame rate and the first
  frame's time in its metadata (``abu measure`` reads them: :mod:`measurement.imaging.frame_rate`);
* ``truth.csv``: per frame the time, the true pixel centres of the three markers, the ball's
  apparent centre (true + lighting offset), theta, beta, omega, omega_dot, beta_dot, omega_ref,
  mu_req and the stick/slip mode (-1, 0, +1 = sign of beta_dot); column names carry units;
* ``meta.json``: fps, the markers' frame-0 positions as ``seeds`` "x,y;x,y;x,y", the geometry,
  the true mu, the simulated slip instant and bounds, and every drive and render setting.

The drive (why not the identified zeta = 0.5, omega_n = 2.2 rad/s): that loop needs about a
second to follow a 1 Hz step, so it lags the 0.5 s staircase by up to 6.9 Hz, its acceleration
never exceeds 130 rad/s^2 and with mu = 0.03 the ball never slips -- unlike the report's
recordings, whose bounds mu_1 = 0.0286 (t = 0.160 s) and mu_2 = 0.0312 (t = 0.245 s) imply
|omega_dot| of 140-250 rad/s^2 and omega on the staircase. The default drive, zeta = 0.7,
omega_n = 12 rad/s with a current-loop lag tau_motor = 20 ms, keeps omega within 2 Hz of the
staircase, gives a continuous acceleration with peaks of about 160-310 rad/s^2, keeps the ball
stuck through the first step (mu_req <= 0.025 for t < 0.11 s at mu = 0.03) and lets it slip at
t ~= 0.20 s, inside the report's window [0.10, 0.33] s. See docs/measurement-imaging.md.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from abu_model.atomic_io import atomic_write_text
from abu_model.errors import AbuError, ParameterError
from abu_model.params import BallParams, PlantParams, check_finite, check_positive

from measurement.imaging.frames_io import write_multipage_tiff
from measurement.report.json_text import dumps
from measurement.imaging.markers import format_seeds
from twin.render import CameraGeometry, RenderSettings, render_frames
from twin.truth_csv import TRUTH_COLUMNS, truth_csv_text  # noqa: F401  (TRUTH_COLUMNS: re-exported)

#: ``kind`` and ``format_version`` of a rendered recording's meta.json (twin and scenarios).
RENDER_META_KIND = "abu-render-meta"
RENDER_META_VERSION = 1

TWO_PI = 2.0 * math.pi



class TwinError(AbuError):
    """The twin cannot be rendered (simulation unavailable or inconsistent with the frames)."""


@dataclass(frozen=True)
class DriveSettings:
    """The speed drive of the twin (PI loop of report eq. 4.5 plus a motor torque lag).

    Attributes:
        zeta: damping ratio of the PI loop [-].
        omega_n: natural frequency of the PI loop [rad/s].
        tau_motor: first-order lag from commanded to applied torque [s].
        theta_ref_mode: ``integral`` (physical PI) or ``thesis`` (theta_ref = t w_ref).
        rounding: staircase rounding (``lead`` = report: first step at t0).
        step: setpoint resolution [rad/s] (2 pi = 1 Hz).
    """

    zeta: float = 0.7
    omega_n: float = 12.0
    tau_motor: float = 0.02
    theta_ref_mode: str = "integral"
    rounding: str = "lead"
    step: float = TWO_PI

    def __post_init__(self) -> None:
        check_positive("zeta", self.zeta, "")
        check_positive("omega_n", self.omega_n, "rad/s")
        if not (math.isfinite(self.tau_motor) and self.tau_motor >= 0):
            raise ParameterError("tau_motor", self.tau_motor, "a time >= 0 s")
        check_positive("step", self.step, "rad/s")


@dataclass(frozen=True)
class TwinSettings:
    """Everything that defines a twin recording (SI units; defaults: report sec. 5.3).

    Attributes:
        mu: true static friction coefficient [-].
        mu_d: sliding friction coefficient [-]; None = mu (the report's choice).
        omega0, omega_end: staircase from omega0 to omega_end [rad/s] (clockwise: negative).
        t0, te: start and duration of the inclined sine [s].
        fps: frame rate [frames/s].
        n_frames: number of frames [-].
        record_start: time of frame 0 [s].
        beta0: initial ball angle relative to the CD marker [rad].
        drive: the speed drive.
        geometry: camera mapping (its ``l`` is replaced by the ball's l).
        render: synthetic camera settings.
        seed: seed of the sensor noise generator.
    """

    mu: float = 0.03
    mu_d: float | None = None
    omega0: float = -9.0 * TWO_PI
    omega_end: float = -19.0 * TWO_PI
    t0: float = 0.0
    te: float = 0.5
    fps: float = 4500.0
    n_frames: int = 3072
    record_start: float = 0.0
    beta0: float = 1.0
    ball: BallParams | None = None
    drive: DriveSettings = field(default_factory=DriveSettings)
    geometry: CameraGeometry = field(default_factory=CameraGeometry)
    render: RenderSettings = field(default_factory=lambda: RenderSettings(exposure_fraction=0.25))
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("omega0", "omega_end", "t0", "record_start", "beta0"):
            check_finite(name, getattr(self, name))
        check_positive("te", self.te, "s")
        check_positive("fps", self.fps, "frames/s")
        if isinstance(self.n_frames, bool) or not isinstance(self.n_frames, (int, np.integer)) \
                or self.n_frames < 1:
            raise ParameterError("n_frames", self.n_frames, "an integer >= 1")
        ball = (self.ball or BallParams()).with_(mu=self.mu, mu_d=self.mu_d)
        object.__setattr__(self, "ball", ball)
        object.__setattr__(self, "geometry", replace(self.geometry, l=ball.l))

    @property
    def frame_times(self) -> np.ndarray:
        """Time of each frame [s]."""
        return self.record_start + np.arange(self.n_frames) / self.fps

    def with_(self, **changes: Any) -> "TwinSettings":
        """A copy with ``changes`` applied (validated again)."""
        return replace(self, **changes)


def _experiment(s: TwinSettings):
    """The harness's StaircaseExperiment for these settings."""
    try:
        from harness.experiments.staircase import StaircaseExperiment
    except ImportError as exc:  # pragma: no cover - the harness is part of the project
        raise TwinError(f"the co-simulation (harness.experiments.staircase) is not available: {exc}") from None
    d = s.drive
    plant = PlantParams(ball=s.ball, tau_motor=d.tau_motor)
    t_last = float(s.frame_times[-1])
    return StaircaseExperiment(
        plant=plant, omega0=s.omega0, omega_end=s.omega_end, t0=s.t0, te=s.te,
        t_end=t_last + 1.0 / s.fps, step=d.step, rounding=d.rounding,
        theta_ref_mode=d.theta_ref_mode, zeta=d.zeta, omega_n=d.omega_n,
        comm_step=1.0 / s.fps, beta0=s.beta0,
        t_start=min(s.record_start, s.t0) - 0.05)


def sample_at_frames(table: dict[str, np.ndarray], times: np.ndarray) -> dict[str, np.ndarray]:
    """The co-simulation's state at the frame times.

    Rows with ``side >= 0`` (right limits at discontinuities) are used; a frame time that is a
    communication point (within 1 ns) takes that row. Between points theta and beta are cubic
    Hermite interpolants of (theta, omega) and (beta, beta_dot), omega of (omega, alpha), and
    alpha, mu_req, omega_ref and the mode are taken from the row before (piecewise constant
    in mode; alpha linear).
    """
    keep = table["side"] >= 0
    t = np.asarray(table["time"], dtype=float)[keep]
    order = np.argsort(t, kind="stable")
    rows = {k: np.asarray(v)[keep][order] for k, v in table.items()}
    t = t[order]
    # duplicates left (side +1 after side 0 at the same time): keep the last one
    last = np.r_[t[1:] != t[:-1], True]
    rows = {k: v[last] for k, v in rows.items()}
    t = t[last]
    if times[0] < t[0] - 1e-9 or times[-1] > t[-1] + 1e-9:
        raise TwinError(f"the simulation covers [{t[0]:g}, {t[-1]:g}] s, the frames "
                        f"[{times[0]:g}, {times[-1]:g}] s")
    i = np.clip(np.searchsorted(t, times - 1e-9), 0, len(t) - 1)
    exact = np.abs(t[i] - times) <= 1e-9
    j = np.where(exact, i, np.clip(i - 1, 0, len(t) - 2))  # interval start for the others
    out = {k: np.asarray(rows[k][np.where(exact, i, j)], dtype=float)
           for k in ("theta", "omega", "alpha", "beta", "beta_dot", "mu_req", "mode",
                     "omega_ref")}
    if not exact.all():
        k0 = j[~exact]
        k1 = k0 + 1
        h = t[k1] - t[k0]
        u = (times[~exact] - t[k0]) / h

        def hermite(p: str, dp: str) -> np.ndarray:
            p0, p1, m0, m1 = rows[p][k0], rows[p][k1], rows[dp][k0] * h, rows[dp][k1] * h
            return ((2 * u ** 3 - 3 * u ** 2 + 1) * p0 + (u ** 3 - 2 * u ** 2 + u) * m0
                    + (-2 * u ** 3 + 3 * u ** 2) * p1 + (u ** 3 - u ** 2) * m1)

        out["theta"][~exact] = hermite("theta", "omega")
        out["beta"][~exact] = hermite("beta", "beta_dot")
        out["omega"][~exact] = hermite("omega", "alpha")
        out["alpha"][~exact] = rows["alpha"][k0] + u * (rows["alpha"][k1] - rows["alpha"][k0])
    out["mode"] = out["mode"].astype(int)
    return out


def _truth_csv(times: np.ndarray, centre, cd, ball, apparent, st: dict[str, np.ndarray]) -> str:
    values = {"time_s": times, "x_center_px": centre[:, 0], "y_center_px": centre[:, 1],
              "x_cd_px": cd[:, 0], "y_cd_px": cd[:, 1], "x_ball_px": ball[:, 0],
              "y_ball_px": ball[:, 1], "x_ball_apparent_px": apparent[:, 0],
              "y_ball_apparent_px": apparent[:, 1], "theta_rad": st["theta"],
              "beta_rad": st["beta"], "omega_rad_s": st["omega"],
              "omega_dot_rad_s2": st["alpha"], "beta_dot_rad_s": st["beta_dot"],
              "omega_ref_rad_s": st["omega_ref"], "mu_req": st["mu_req"], "mode": st["mode"]}
    return truth_csv_text(TRUTH_COLUMNS, values)


def simulate_twin(settings: TwinSettings | None = None, *, fmu_dir: Any = None):
    """Run the co-simulation and sample it at the frame times.

    Returns (state at frames dict, true pixel positions (centre, cd, ball) each (N, 2),
    ExperimentResult).
    """
    s = settings or TwinSettings()
    from harness.experiments.staircase import run_staircase

    exp = _experiment(s)
    res = run_staircase(exp, fmu_dir)
    times = s.frame_times
    state = sample_at_frames(res.table, times)
    positions = s.geometry.marker_positions(state["theta"], state["beta"])
    return state, positions, res


def render_twin(out_dir: str | Path, settings: TwinSettings | None = None, *,
                fmu_dir: Any = None) -> Path:
    """Simulate and film the experiment; write frames.tif, truth.csv and meta.json.

    Args:
        out_dir: output folder (created if needed).
        settings: the twin's settings (defaults: report sec. 5.3, mu = 0.03).
        fmu_dir: where the FMUs are (see :func:`harness.experiments.staircase.ensure_fmus`).

    Returns:
        ``out_dir`` as a Path.
    """
    s = settings or TwinSettings()
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise TwinError(f"output '{out}' exists and is not a folder")
    state, (centre, cd, ball), res = simulate_twin(s, fmu_dir=fmu_dir)
    times = s.frame_times
    g = s.geometry
    for name, p in (("CD marker", cd), ("ball", ball), ("ABU centre", centre)):
        margin = 16.0
        if (p[:, 0].min() < margin or p[:, 1].min() < margin
                or p[:, 0].max() > s.render.width - 1 - margin
                or p[:, 1].max() > s.render.height - 1 - margin):
            raise ParameterError("geometry", asdict(g),
                                 f"the {name} within the {s.render.width}x{s.render.height} px "
                                 f"frame with a {margin:g} px margin for the tracking window")
    frames = render_frames(centre, cd, ball, s.render, seed=s.seed)
    apparent = ball + s.render.ball_shift_vector
    summary = res.summary
    meta = {
        "kind": RENDER_META_KIND, "format_version": RENDER_META_VERSION,
        "description": "digital twin of the report's experiment (sec. 5.3): FMI co-simulation "
                       "rendered by twin.render",
        "files": {"frames": "frames.tif", "truth": "truth.csv"},
        "fps": s.fps, "frame_interval_s": 1.0 / s.fps, "n_frames": s.n_frames,
        "time_first_frame_s": float(times[0]),
        "frame_size_px": [s.render.width, s.render.height],
        # where the camera sees the markers in frame 0 (the ball at its apparent centre)
        "seeds": format_seeds(np.stack([centre[0], cd[0], apparent[0]])),
        "seeds_roles": ["centre", "cd", "ball"],
        "geometry": {"l_m": s.ball.l, "d_m": s.ball.d, "m_kg": s.ball.m, "r_cd_m": g.r_cd,
                     "pixel_size_m_per_px": g.pixel_size, "centre_x_px": g.centre_x,
                     "centre_y_px": g.centre_y, "l_px": g.l_px, "r_cd_px": g.r_cd_px,
                     "convention": "x = column, y = row (down); theta = atan2(-(y_cd - y_c), "
                                   "x_cd - x_c), counter-clockwise on screen positive; beta = "
                                   "angle(centre->ball) - theta"},
        "mu": s.mu, "mu_d": s.ball.mu_dynamic,
        "simulation": {
            "t_slip_s": summary.get("t_slip"), "mu_low": summary.get("mu_low"),
            "mu_high": summary.get("mu_high"), "switches": summary.get("switches"),
            "max_mu_req_in_frames": float(np.max(state["mu_req"])),
            "omega_dot_peak_rad_s2": float(np.max(np.abs(state["alpha"]))),
            "mode_first_frame": int(state["mode"][0]),
            "first_slip_frame": (int(np.flatnonzero(state["mode"] != 0)[0])
                                 if np.any(state["mode"] != 0) else None),
        },
        "experiment": {"omega0_rad_s": s.omega0, "omega_end_rad_s": s.omega_end,
                       "omega0_hz": s.omega0 / TWO_PI, "omega_end_hz": s.omega_end / TWO_PI,
                       "t0_s": s.t0, "te_s": s.te, "beta0_rad": s.beta0},
        "drive": {"zeta": s.drive.zeta, "omega_n_rad_s": s.drive.omega_n,
                  "tau_motor_s": s.drive.tau_motor, "theta_ref_mode": s.drive.theta_ref_mode,
                  "rounding": s.drive.rounding, "step_rad_s": s.drive.step,
                  "J_abu_kg_m2": PlantParams().J_abu},
        "render": s.render.to_dict(),
        "ball_apparent_offset_px": s.render.ball_shift_vector.tolist(),
        "seed": s.seed,
        "units": {"fps": "frames/s", "mu": "1", "mu_d": "1", "seeds": "px"},
    }
    out.mkdir(parents=True, exist_ok=True)
    write_multipage_tiff(out / "frames.tif", frames, fps_hz=s.fps,
                         first_frame_time_s=float(times[0]))
    atomic_write_text(out / "truth.csv", _truth_csv(times, centre, cd, ball, apparent, state))
    atomic_write_text(out / "meta.json", dumps(meta))
    return out


# ------------------------------------------------------------------------- command line
