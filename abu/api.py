"""The public Python API of abu-friction: everything the ``abu`` command line does, for scripts
and notebooks, in one place (``from abu import api``).

Units: SI throughout (s, m, kg, rad, rad/s, rad/s^2). Speeds are rad/s unless the name ends in
``_hz``: every speed argument here is in Hz, as on the command line and on the setup's
controller, and :func:`hz` converts one to rad/s for the lower-level classes.

Simulate (FMI co-simulation, report ch. 4)::

    result = api.simulate_staircase(mu=2.75e-3, omega0_hz=-17, omega_end_hz=-22)
    result.mu_low, result.mu_high, result.t_slip_s

Measure (camera recording -> interval on mu, report ch. 5)::

    api.render("twin")                      # a synthetic recording of known mu (0.03)
    m = api.measure("twin")                 # track + analyse (frame rate from frames.tif)
    m.mu_low, m.mu_high, m.status
    api.write_measurement(m, "out")         # tracks.csv, kinematics.csv, figures, summary.json

Plan: :func:`design` (a staircase for a prior range of mu), :func:`identify` (the speed loop
from a record), :func:`propose_next` (the run that narrows an interval most), and
:func:`combine` (several records' intervals).

Every result object has the fields of the JSON summary the command line writes
(``.summary``), with typed properties for the main ones.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

from abu_model.params import BallParams, PlantParams

from measurement.inference.analysis import AnalysisOptions
from measurement.pipeline import (DEFAULT_D_M, DEFAULT_L_M, MarkerTracks,  # noqa: F401 (API)
                                  MeasureResult, TrackingSettings, summary_field, measure_recording,
                                  measure_tracks_file, track_recording, write_measurement,
                                  write_tracks)

__all__ = ["hz", "BallParams", "PlantParams", "SimulationResult", "simulate_staircase",
           "table41", "render", "render_random", "track", "measure", "measure_tracks",
           "write_measurement", "write_tracks", "combine", "identify", "design",
           "propose_next", "MeasureResult", "MarkerTracks", "TrackingSettings",
           "AnalysisOptions"]

#: rad/s per Hz.
RAD_S_PER_HZ = 2.0 * math.pi


def hz(speed_hz: float) -> float:
    """A speed in Hz (revolutions per second) as rad/s."""
    return float(speed_hz) * RAD_S_PER_HZ


# ------------------------------------------------------------------------------ simulate

@dataclass
class SimulationResult:
    """One co-simulated experiment: the recorded table, the summary of ``summary.json``.

    Attributes:
        summary: bounds, slip instant, switches, the experiment's settings, run statistics.
        result: the harness's full result (``.table``: column -> array, SI units).
    """

    summary: dict[str, Any]
    result: Any

    mu = summary_field("mu", "true (simulated) static friction coefficient [-]")
    mu_low = summary_field("mu_low", "largest mu_req while stuck [-]; None when the first "
                                      "setpoint step made the ball slip")
    mu_high = summary_field("mu_high", "mu_req just after the slip [-]; None: no slip")
    t_slip_s = summary_field("t_slip", "first slip instant [s] (None: no slip)")
    omega_slip_rad_s = summary_field("omega_slip", "ABU speed at the slip [rad/s]")
    alpha_slip_rad_s2 = summary_field("alpha_slip", "ABU acceleration at the slip [rad/s^2]")
    slips = summary_field("slips", "whether the ball slipped in the run")
    brackets_mu = summary_field("brackets_mu", "whether mu_low <= mu < mu_high")
    switches = summary_field("switches", "every stick/slip switch (time [s], from, to)")
    message = summary_field("message", "what the bounds mean for this run")

    def write(self, out_dir: str | Path, figure_format: str = "png") -> list[Path]:
        """``result.csv``, ``summary.json`` and the figures (png, pdf or svg) into ``out_dir``
        (created)."""
        from harness.experiments.simulate_output import write_outputs

        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        return write_outputs(self.result, out, figure_format)


def simulate_staircase(*, mu: float = 2.75e-3, mu_d: float | None = None,
                       omega0_hz: float = -17.0, omega_end_hz: float = -22.0,
                       t0_s: float = 0.0, te_s: float = 1.0, t_end_s: float | None = None,
                       step_hz: float = 1.0, rounding: str = "lead",
                       theta_ref: str = "integral", zeta: float = 0.5,
                       omega_n_rad_s: float = 2.2, tau_motor_s: float = 0.0,
                       ball: BallParams | None = None, tol: float | None = None,
                       fmu_dir: str | Path | None = None) -> SimulationResult:
    """Co-simulate the report's staircase experiment (sec. 4.2) on the FMUs.

    Args:
        mu, mu_d: static and sliding friction [-] (mu_d None: = mu).
        omega0_hz, omega_end_hz: initial speed and end of the inclined sine [Hz]
            (negative: clockwise, the report's).
        t0_s, te_s, t_end_s: start and duration of the sine, end of the run [s].
        step_hz: setpoint resolution [Hz]; rounding: ``lead``, ``nearest`` or ``trail``.
        theta_ref: ``integral`` (physical PI) or ``thesis`` (the report's literal reading).
        zeta, omega_n_rad_s: the identified closed loop [-], [rad/s].
        tau_motor_s: motor torque lag [s].
        ball: ball geometry (its mu, mu_d replaced by ``mu``, ``mu_d``); None: the report's.
        tol: coupling error tolerance (None: 1e-9).
        fmu_dir: built FMUs (``abu build-fmus``); None: built into a temporary folder.
    """
    from dataclasses import replace

    from harness.experiments.staircase import StaircaseExperiment, run_staircase

    b = replace(ball or BallParams(), mu=mu, mu_d=mu_d)
    exp = StaircaseExperiment(PlantParams(b, tau_motor=tau_motor_s), hz(omega0_hz),
                              hz(omega_end_hz), t0=t0_s, te=te_s, t_end=t_end_s,
                              step=hz(step_hz), rounding=rounding, theta_ref_mode=theta_ref,
                              zeta=zeta, omega_n=omega_n_rad_s, tol=tol)
    result = run_staircase(exp, fmu_dir)
    return SimulationResult(result.summary, result)


def table41(mus: Sequence[float], *, theta_ref: str = "integral", step_hz: float = 1.0,
            check: bool = True, fmu_dir: str | Path | None = None) -> list[dict[str, Any]]:
    """Report Table 4.1: for each mu the smallest integer |omega0| [Hz] at which one setpoint
    step keeps the ball stuck (``omega0_hz``), checked by co-simulation when ``check``."""
    from harness.experiments.table41 import table41 as run

    return [row.as_dict() for row in run(list(mus), theta_ref_mode=theta_ref, step_hz=step_hz,
                                         check=check, fmu_dir=fmu_dir)]


# ------------------------------------------------------------------------------ measure

def render(out_dir: str | Path, *, mu: float = 0.03, seed: int = 0,
           fmu_dir: str | Path | None = None) -> Path:
    """Render the report's camera twin (sec. 5.3: -9 Hz -> -19 Hz in 0.5 s, 4500 frames/s) with
    true friction ``mu`` into ``out_dir``: ``frames.tif``, ``truth.csv``, ``meta.json``."""
    from twin.report_twin import TwinSettings, render_twin

    return render_twin(out_dir, TwinSettings().with_(mu=mu, seed=seed), fmu_dir=fmu_dir)


def render_random(out_dir: str | Path, seed: int, *, size_px: int = 256,
                  lighting: str | None = None) -> Path:
    """Render one recording of the harsh random family (``abu render --scenario random``):
    mu, drive, lamps, lens and sensor drawn from ``seed``."""
    from twin.scenario import random_scenario, render_scenario

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    render_scenario(out, random_scenario(seed, size=size_px, lighting=lighting))
    return out


def track(recording: str | Path, *, fps_hz: float | None = None,
          settings: TrackingSettings = TrackingSettings()) -> MarkerTracks:
    """Marker tracks of a recording (camera file, TIFF stack, frames folder, ``.npy``, video).

    Args:
        fps_hz: frame rate [frames/s]; None: the rate the file states (Photron CIH/CIHX,
            Phantom CINE, a TIFF of :func:`render`), and an error naming ``fps_hz`` for files
            that state none (video, ``.npy``, frame folders, other TIFFs). Given, it overrides
            the file's rate (a :class:`UserWarning` when they differ).
    """
    return track_recording(recording, fps_hz=fps_hz, settings=settings, fps_option="fps_hz")


def measure(recording: str | Path, *, fps_hz: float | None = None,
            tracking: TrackingSettings = TrackingSettings(), l_m: float = DEFAULT_L_M,
            d_m: float = DEFAULT_D_M, options: AnalysisOptions = AnalysisOptions(),
            camera: str | Path | None = None) -> MeasureResult:
    """Track and analyse a recording: the confidence interval on mu (``abu measure``).

    Args:
        fps_hz: frame rate [frames/s] (None: the rate the file states; as :func:`track`).
        l_m, d_m: radius of the ball centre's path and ball diameter [m].
        options: the analysis settings (confidence level, estimator, ...).
        camera: ``camera.json`` of ``abu calibrate-camera`` (undistorts the tracks).
    """
    cam = _camera(camera)
    return measure_recording(recording, fps_hz=fps_hz, tracking=tracking, l_m=l_m, d_m=d_m,
                             options=options, camera=cam, fps_option="fps_hz",
                             camera_path=None if camera is None else str(camera))


def measure_tracks(tracks_csv: str | Path, *, l_m: float = DEFAULT_L_M,
                   d_m: float = DEFAULT_D_M, options: AnalysisOptions = AnalysisOptions(),
                   camera: str | Path | None = None,
                   ball_reflections: int | None = None) -> MeasureResult:
    """Analyse a tracks CSV (``abu measure --tracks``).

    Args:
        ball_reflections: how the tracked ball looked (1 or 2; None: not stated, as the CSV
            does not say); with 2 the default analysis keeps both lighting models.
    """
    cam = _camera(camera)
    return measure_tracks_file(tracks_csv, l_m=l_m, d_m=d_m, options=options, camera=cam,
                               camera_path=None if camera is None else str(camera),
                               ball_reflections=ball_reflections)


def _camera(path: str | Path | None):
    if path is None:
        return None
    from measurement.imaging.camera import read_camera
    return read_camera(path)


def combine(summaries: Sequence[str | Path], *, bins: int = 100) -> dict[str, Any]:
    """Several records' intervals (summary.json files or CSVs with mu_low,mu_high): the
    histogram of report fig. 5.11, the common and majority ranges, the Turnbull estimate."""
    from measurement.report.multi import combine_summaries, read_intervals

    return combine_summaries(read_intervals(list(summaries)), bins=bins)


# ------------------------------------------------------------------------------ plan

def identify(record_csv: str | Path, setpoints_csv: str | Path, *, model: str = "pi-lag"):
    """Fit the closed speed loop (zeta, omega_n, tau_motor, setpoint weight) to a speed or angle
    record (``abu identify --record``); returns a ``harness.planning.identify.IdentifyResult``
    (``.drive`` is what ``drive.json`` holds)."""
    from harness.planning.identify import fit_drive
    from harness.planning.record_io import read_record, read_setpoints

    return fit_drive(read_record(record_csv), read_setpoints(setpoints_csv), model)


def design(mu_lo: float, mu_hi: float, **spec: Any):
    """Plan the staircase for the prior range [mu_lo, mu_hi] (``abu design``); ``spec``: the
    other fields of ``harness.planning.design.DesignSpec`` (drive, camera, limits)."""
    from harness.planning.design import DesignSpec, design_staircase

    return design_staircase(DesignSpec(mu_lo, mu_hi, **spec))


def propose_next(summaries: Sequence[str | Path], **spec: Any):
    """The run that narrows the combined interval of ``summaries`` most (``abu next``)."""
    from abu.intervals_io import read_intervals
    from harness.planning.design import DesignSpec
    from harness.planning.next_run import combine as intersect, propose_next as propose

    intervals = read_intervals(list(summaries))
    lo, hi = intersect(intervals)
    return propose(intervals, DesignSpec(lo, hi, **spec))
