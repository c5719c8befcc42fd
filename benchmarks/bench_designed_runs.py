"""Does ``abu design`` predict what ``abu measure`` delivers? Designed runs, rendered and measured.

For each prior range (a factor of 2 wide) and drive, ``abu design --json --no-check`` plans the
staircase; each run then draws a true mu log-uniformly across the range and mu_d / mu uniformly
in [0.6, 1], takes the lighting, lens, sensor and set-up of the harsh twin's
``twin.scenario.random_scenario(seed)`` (random lighting and lens; the drawn drive is replaced by
the designed staircase on the drive, a digital PI loop at the frame rate with the drive's torque
lag and setpoint weight), renders the recording of the design's length and measures it with
``abu measure``. Printed, per slice of seeds and overall:

* measured / predicted relative width (``relative_width`` of ``abu measure``, (hi - lo) / mid,
  against ``harness.planning.width_model``'s expected width at the true mu and at mu_d / mu = 0.8)
  and the share within [0.77, 1.3] (target >= 90 %), the share inside the predicted 90 % range;
* the same ratio with the camera's noise known (this run's measured theta and beta noise, what
  an earlier recording of the same set-up states: ``--noise-from``, ``abu next``);
* the share of runs with both bounds finite (target: all), coverage of the stated 95 %
  (target >= 95 %), the median measured width (the report's single run: 8.7 %), and what sets
  it: the medians of ``abu measure``'s own parts (beta profile, lens prior, truncation bound,
  kinematic noise).

The width model's constants were calibrated on seeds 0-71 (``--calibrate ROWS`` on the rows of
a run with ``--first 0``, whose designs came from the noise-free ranking of the code before the
width model); the validation slice, seeds 1000-1071 with the designs of the predicted ranking,
was not used for it. Run (two worker processes, about 30 min on the shared 2-core machine)::

    nice python benchmarks/bench_designed_runs.py --runs 72 --first 1000 --jobs 2
    nice python benchmarks/bench_designed_runs.py --runs 180 --first 1000   # 60 per range,
                                                                  # ~9 min on one core
    nice python benchmarks/bench_designed_runs.py --runs 72 --first 0 --jobs 2 --rows cal.jsonl \
        --design-args="--objective expected"      # the calibration slice's designs
    python benchmarks/bench_designed_runs.py --calibrate cal.jsonl   # fit the constants
    python benchmarks/bench_designed_runs.py --report cal.jsonl      # figures of saved rows

``--rows FILE`` writes one JSON row per run (what ``--calibrate`` and ``--report`` read).

``--kinematics drive-model`` measures each rendered recording a second time, with ``abu measure
--kinematics drive-model``: the design's drive (its ``drive`` object, plus ``sample_time_s`` =
the frame interval, the twin's controller sampling at the frame rate; the designed drives have
no setpoint filter) over the design's staircase (``omega0_hz``, ``omega_end_hz``, ``t0_s``,
``te_s``, ``step_hz``, ``rounding``: the staircase the twin's controller followed, on the
record's clock). Printed beside the default: refusals (and why), finite bounds, coverage, the
median width, and measured / predicted width against the same (default-kinematics) predictor::

    nice python benchmarks/bench_designed_runs.py --runs 72 --first 1000 --kinematics drive-model

``--camera VIEWS`` calibrates each run's lens on that many chessboard views through its own
optics (``lens_calibration.calibrate``, ``abu calibrate-camera``) and measures with ``abu
measure --camera`` (both measurements); the predictions take the calibration's lens prior (a
user's ``--noise-from`` summary measured with the camera states it), and the report prints the
priors' spread::

    nice python benchmarks/bench_designed_runs.py --runs 72 --first 1000 --jobs 2 --camera 30

What-ifs of that second measurement (not options of ``abu measure``): ``--free-setpoint-weight``
declares a ``pi-lag`` drive as ``pi-lag-weighted`` (the setpoint weight fitted from 1: the
twin's forward-Euler frame-rate integrator leaves a non-white residual when b is held at 1),
``--timing-samples`` the drive model's timing bar (``TIMING_SAMPLES``; 0: none; the twin's
frames are its controller's samples, a real camera's are not), ``--error-rel`` and
``--max-evaluations`` the fit's settings; ``--exact`` measures a third time with the plant's
exact kinematics (``bench_width_floor.exact_kinematics``: the floor no kinematics can beat).

``--ideal-ball`` analyses each run's tracks (``tracks.csv`` of the measurement, with its
camera) again at the tracks level four ways: as tracked (which repeats ``abu measure``'s
width), with the exact kinematics, with the ball at its true centre plus the tracker's white
noise (``ideal_ball.py``: beta as a perfect lighting model would leave it), and both: what a
clean beta and perfect kinematics would give, the floor of this camera's tracking noise.
``--zoom Z`` films every run Z times closer (``twin.scenario.magnified``, frames Z x 256 px):
the ball's tracking noise in rad falls about as 1 / Z. ::

    nice python benchmarks/bench_designed_runs.py --runs 72 --first 1000 --jobs 2 --camera 30 \
        --ideal-ball
    nice python benchmarks/bench_designed_runs.py --runs 72 --first 5000 --jobs 2 --camera 30 \
        --zoom 2 --ideal-ball

Measured (twelfth session): seeds 1000-1071 at 1x, medians as tracked 13.0 %, clean beta
11.9 %, exact motion 10.5 %, both 9.0 % (531 s wall; seeds 3000-3071: 13.5 %, 11.9 %,
10.2 %, 9.0 %); seeds 5000-5071 at 2x: 7.8 %, 7.2 %,
7.1 %, 6.8 %, coverage 95.8 %, theta's and beta's noise 1.11e-4 and 3.37e-4 rad (1x:
2.73e-4, 6.07e-4), 1945 s wall on the shared machine; ``--runs 36 --first 7000 --zoom 2
--camera 30``: 6.8 %, coverage 97.2 %, beta's noise 3.0e-4 rad.
"""
from __future__ import annotations

import argparse
import io
import json
import math
import os
import sys
import tempfile
import time
from contextlib import redirect_stderr, redirect_stdout
from dataclasses import replace
from multiprocessing import Pool
from pathlib import Path

from bench_args import positive_int  # the scripts' folder is on sys.path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from abu.cli.main import main as abu_main  # noqa: E402
from controller.drive import Drive  # noqa: E402
from twin.drives import DriveSpec  # noqa: E402
from twin.scenario import (magnified, random_scenario, render_scenario_frames,  # noqa: E402
                          simulate_scenario)

TWO_PI = 2.0 * math.pi
RANGES = ((0.01, 0.02), (0.02, 0.04), (0.03, 0.06))
#: the report's loop, and PI loops with 5-25 ms torque lags and setpoint weights
DRIVES = {"report loop": Drive(),
          "PI 5 ms": Drive("pi-lag", 0.7, 12.0, 0.005),
          "PI 15 ms b 0.8": Drive("pi-lag-weighted", 0.9, 20.0, 0.015, 0.8),
          "PI 25 ms b 0.6": Drive("pi-lag-weighted", 0.8, 15.0, 0.025, 0.6)}
RATIO_BAND = (0.77, 1.3)
#: Options added to every ``abu measure`` of the designed runs (``--no-edge-step``: the
#: contour fits alone, the tracker the width model was calibrated with).
EXTRA_MEASURE_ARGS: list[str] = []
#: Measure each recording a second time with these kinematics too (``--kinematics``).
SECOND_KINEMATICS: list[str] = []
#: What-ifs of that second measurement: a ``pi-lag`` drive declared ``pi-lag-weighted`` (its
#: setpoint weight fitted from 1: ``--free-setpoint-weight``).
DRIVE_MODEL_WHAT_IF: dict[str, bool] = {"free_setpoint_weight": False, "exact": False}
#: ``--camera N``: calibrate each run's lens on N chessboard views and measure with ``--camera``
CAMERA_VIEWS: list[int] = []
#: ``--zoom Z``: every run filmed Z times closer (pixel size / Z, frames Z x 256 px wide)
ZOOM: list[float] = []
#: ``--ideal-ball``: the tracks analysed again with the ball at its true centre plus the
#: tracker's white noise (``ideal_ball.py``: beta as a perfect lighting model leaves it)
IDEAL_BALL = {"on": False}
MU_D_RATIO = (0.6, 1.0)


def configs() -> list[tuple[tuple[float, float], str]]:
    """Every (range, drive name) pair, in a fixed order."""
    return [(r, d) for d in DRIVES for r in RANGES]


def run_design(mu_range: tuple[float, float], drive_name: str, extra: list[str]) -> dict:
    """``abu design --json --no-check`` for the range and drive; its JSON."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "drive.json"
        path.write_text(json.dumps(DRIVES[drive_name].to_dict()))
        out = io.StringIO()
        with redirect_stdout(out), redirect_stderr(io.StringIO()):
            status = abu_main(["design", "--mu-range", repr(mu_range[0]), repr(mu_range[1]),
                               "--drive", str(path), "--json", "--no-check", *extra])
    if status != 0:
        raise SystemExit(f"abu design failed for {mu_range} {drive_name} (exit {status})")
    return json.loads(out.getvalue())


def draw(seed: int, mu_range: tuple[float, float]) -> tuple[float, float]:
    """True (mu, mu_d) of a run: mu log-uniform over the range, mu_d / mu uniform."""
    rng = np.random.default_rng([seed, 7])
    lo, hi = mu_range
    mu = lo * (hi / lo) ** rng.uniform()
    return mu, mu * rng.uniform(*MU_D_RATIO)


def staircase_drive(design: dict, drive: Drive) -> DriveSpec:
    """The designed staircase on the drive, as the twin's digital PI loop."""
    return DriveSpec(kind="staircase_pi", omega0=design["omega0_hz"] * TWO_PI,
                     omega_end=design["omega_end_hz"] * TWO_PI, t0=design["t0_s"],
                     te=design["te_s"], step=design["step_hz"] * TWO_PI,
                     rounding=design["rounding"], zeta=drive.zeta, omega_n=drive.omega_n,
                     tau_motor=drive.tau_motor, setpoint_weight=drive.setpoint_weight)


def render_measure(scn, design: dict, drive_name: str, out: Path) -> tuple[int, dict, dict]:
    """Render the designed staircase on the drive with the scenario's ball, lighting, lens and
    sensor, and measure it into ``out`` with ``abu measure``: (exit status, the scenario as
    rendered and its true state, the summary or {})."""
    frames_n = int(round(design["record_s"] * design["fps_hz"])) + 1
    scn = replace(scn, drive=staircase_drive(design, DRIVES[drive_name]), n_frames=frames_n,
                  predicted_slip_s=None)
    state, pos = simulate_scenario(scn)
    frames = render_scenario_frames(scn, state, pos)
    out.mkdir(parents=True, exist_ok=True)
    rec = out / "rec.npy"
    np.save(rec, frames)
    args = ["measure", str(rec), "--out", str(out / "m"), "--quiet", "--no-plots",
            "--fps", repr(scn.fps), "--l", repr(scn.ball.l), "--d", repr(scn.ball.d)]
    if scn.lighting.reflections == 2:
        args += ["--ball-reflections", "2"]
    cam = None
    if CAMERA_VIEWS:   # the lens calibrated as a user would, before recording
        sys.path.insert(0, str(Path(__file__).resolve().parent))
        from lens_calibration import calibrate
        cam, _ = calibrate(scn, out, CAMERA_VIEWS[0])
        args += ["--camera", str(cam)]
    args += EXTRA_MEASURE_ARGS
    with redirect_stdout(io.StringIO()), redirect_stderr(io.StringIO()):
        status = abu_main(args)
    if SECOND_KINEMATICS:
        s2 = measure_drive_model(rec, args, design, scn.fps, out)
    if DRIVE_MODEL_WHAT_IF["exact"]:
        s3 = measure_exact(args, state, out)
    rec.unlink()
    summary = json.loads((out / "m" / "summary.json").read_text()) if status == 0 else {}
    if IDEAL_BALL["on"] and status == 0:
        summary["ideal"] = ideal_ball_widths(scn, state, pos, out / "m" / "tracks.csv", cam)
    if SECOND_KINEMATICS:
        summary["second"] = s2
    if DRIVE_MODEL_WHAT_IF["exact"]:
        summary["exact"] = s3
    return status, {"scenario": scn, "state": state}, summary


def ideal_ball_widths(scn, state: dict, pos: dict, tracks_csv: Path, cam: Path | None
                      ) -> dict:
    """``--ideal-ball``: the measured tracks analysed at the tracks level (as ``abu measure``,
    with the run's camera) four ways: as tracked, and with the ball at its true centre plus the
    tracker's white noise (``ideal_ball.py``), each with the measured and with the exact
    kinematics; the ball's error parts [px]. {name: relative width (NaN without both bounds)}."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_width_floor import summary as tracks_summary
    from ideal_ball import ball_error, ideal_ball

    from measurement.imaging.camera import read_camera
    from measurement.imaging.tracks_io import read_tracks_csv
    from measurement.inference.analysis import AnalysisOptions

    t = read_tracks_csv(tracks_csv)
    err = ball_error(np.c_[t.x[:, 2], t.y[:, 2]], pos["ball"])
    x, y = ideal_ball(t.x, t.y, pos["ball"], err.white_px, scn.seed)
    ideal = replace(t, x=x, y=y, lost=t.lost | ~np.isfinite(x))
    camera = read_camera(cam) if cam is not None else None
    out = {"ball_white_px": err.white_px, "ball_leftover_px": err.leftover_px}
    for name, tracks, exact in (("tracked", t, False), ("tracked_exact", t, True),
                                ("ideal", ideal, False), ("ideal_exact", ideal, True)):
        s = tracks_summary(scn, tracks, AnalysisOptions(), state if exact else None, camera)
        lo, hi = s["mu_low"], s["mu_high"]
        out[name] = ((hi - lo) / (0.5 * (hi + lo)) if lo is not None and hi is not None
                     and lo > 0 and math.isfinite(hi) else math.nan)
        out[name + "_covers"] = bool((lo or 0.0) <= scn.ball.mu <= (hi if hi is not None
                                                                   else math.inf))
    return out


def measure_exact(args: list[str], state: dict, out: Path) -> dict:
    """The same recording measured with the plant's exact omega and omega_dot (~0 bars), the
    floor no kinematics can beat (``bench_width_floor.exact_kinematics``); its summary."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_width_floor import exact_kinematics

    from measurement.inference import analysis
    args = [*args[:args.index("--out") + 1], str(out / "ex"), *args[args.index("--out") + 2:]]
    measured = analysis._kinematics
    analysis._kinematics = exact_kinematics(state)
    try:
        with redirect_stdout(io.StringIO()), redirect_stderr(io.StringIO()):
            status = abu_main(args)
    finally:
        analysis._kinematics = measured
    return json.loads((out / "ex" / "summary.json").read_text()) if status == 0 else {}


def measure_drive_model(rec: Path, args: list[str], design: dict, fps: float, out: Path
                        ) -> dict:
    """The same recording measured with ``--kinematics drive-model``: the design's drive with
    the twin's controller sample time (the frame interval) over the design's staircase; the
    summary ({"exit": status} when the command failed)."""
    drive = {k: v for k, v in design["drive"].items() if k not in ("units", "source")}
    drive["sample_time_s"] = 1.0 / fps
    if DRIVE_MODEL_WHAT_IF["free_setpoint_weight"] and drive["model"] == "pi-lag":
        drive["model"] = "pi-lag-weighted"
    path = out / "drive.json"
    path.write_text(json.dumps(drive))
    args = [*args[:args.index("--out") + 1], str(out / "dm"), *args[args.index("--out") + 2:],
            "--kinematics", "drive-model", "--drive", str(path),
            "--omega0-hz", repr(float(design["omega0_hz"])),
            "--omega-end-hz", repr(float(design["omega_end_hz"])),
            "--t0", repr(float(design["t0_s"])), "--te", repr(float(design["te_s"])),
            "--step-hz", repr(float(design["step_hz"])), "--rounding", design["rounding"]]
    err = io.StringIO()
    with redirect_stdout(io.StringIO()), redirect_stderr(err):
        status = abu_main(args)
    if status != 0:
        return {"exit": status, "error": err.getvalue().strip()[-300:]}
    s = json.loads((out / "dm" / "summary.json").read_text())
    s["exit"] = 0
    return s


def one(job: tuple) -> dict:
    """Render and measure one designed run; its row (measured and predicted)."""
    seed, mu_range, drive_name, design = job
    mu, mu_d = draw(seed, mu_range)
    frames_n = int(round(design["record_s"] * design["fps_hz"])) + 1
    scn = random_scenario(seed, n_frames=max(frames_n, 1000),
                          **({"size": int(round(256 * ZOOM[0]))} if ZOOM else {}))
    if ZOOM:   # a camera ZOOM times closer, the frame grown to hold the ABU (bench_off_family)
        scn = magnified(scn, ZOOM[0])
    scn = replace(scn, ball=replace(scn.ball, mu=mu, mu_d=mu_d))
    with tempfile.TemporaryDirectory() as tmp:
        status, truth, s = render_measure(scn, design, drive_name, Path(tmp))
    state = truth["state"]
    row = {"seed": seed, "mu_range": list(mu_range), "drive": drive_name, "mu": mu,
           "mu_d": mu_d, "design": {k: design[k] for k in (
               "omega0_hz", "omega_end_hz", "t0_s", "te_s", "rounding", "step_hz", "fps_hz",
               "frames", "record_s")},
           "t_slip_true": float(state["switches"][0]) if len(state["switches"]) else None,
           "reflections": int(scn.lighting.reflections),
           "exposure_fraction": scn.optics.exposure_fraction, "pixel_size_m": scn.pixel_size,
           "exit": status}
    if status != 0:
        return row
    mf, nz = s.get("model_fit") or {}, s.get("noise") or {}
    row.update({k: s.get(k) for k in ("mu_low", "mu_high", "relative_width", "status",
                                      "t_slip")})
    row.update({k: mf.get(k) for k in ("profile_mu_low", "profile_mu_high",
                                       "kinematic_rel_sigma_at_slip",
                                       "kinematic_rel_bias_at_slip", "lower_bound_sup_z",
                                       "sigma_leftover_rad", "leftover_tau_s")})
    row["sigma_white_beta_rad"] = (mf.get("noise_model") or {}).get("sigma_white_rad")
    row["lens_prior_rad"] = ((s.get("camera") or {}).get("theta_harmonic_prior") or {}).get(
        "theta_harmonic_rad")
    if "ideal" in s:
        row["ideal"] = s["ideal"]
    if "exact" in s:
        row["exact"] = {k: s["exact"].get(k) for k in ("mu_low", "mu_high", "relative_width")}
    if "second" in s:
        s2, est = s["second"], s["second"].get("estimator") or {}
        row["drive_model"] = {"exit": s2["exit"], "error": s2.get("error"),
                              "model": est.get("model"), "why": est.get("why"),
                              **{k: s2.get(k) for k in ("mu_low", "mu_high", "relative_width",
                                                        "status", "t_slip")},
                              **{k: (s2.get("model_fit") or {}).get(k) for k in (
                                  "profile_mu_low", "profile_mu_high",
                                  "kinematic_rel_sigma_at_slip", "kinematic_rel_bias_at_slip",
                                  "lower_bound_sup_z")}}
    row.update({k: nz.get(k) for k in ("sigma_theta_rad", "sigma_beta_rad",
                                       "sigma_omega_dot_rad_s2")})
    return row


def predicted(row: dict, design: dict, camera: bool = False, true_mu_d: bool = False,
              kinematics: str = "savgol") -> dict:
    """The width model's prediction for this run's design at its true mu; ``camera``: with
    the camera's noise known (this run's measured theta and beta noise, what an earlier
    recording of the same set-up states: ``abu next`` reads it from the summaries); the lens
    prior is the calibration's wherever the run was measured with ``--camera`` (known before
    the run: the calibration comes first); ``true_mu_d``: told the run's true mu_d / mu (its
    range collapsed onto it; a plan spans 0.6-1 around 0.8); ``kinematics``: those of the
    measurement predicted (``drive-model``: the second measurement)."""
    from harness.planning.design_width import predict_run_width
    from harness.planning.width_model import CALIBRATED, MU_D_RATIOS, with_recorded_setup
    c = replace(CALIBRATED, kinematics=kinematics)
    if row.get("lens_prior_rad") is not None:
        c = replace(c, theta_harmonic_rad=row["lens_prior_rad"])
    k = row["mu_d"] / row["mu"]
    ratios = (k, k, k) if true_mu_d else MU_D_RATIOS
    if camera:
        c = with_recorded_setup(c, [{"noise": {"sigma_theta_rad": row["sigma_theta_rad"]},
                                     "model_fit": {"noise_model": {
                                         "sigma_white_rad": row["sigma_white_beta_rad"],
                                         "sigma_leftover_rad": row["sigma_leftover_rad"]}}}])
    return predict_run_width(design, DRIVES[row["drive"]], row["mu"], constants=c,
                             mu_d_ratios=ratios)


def add_predictions(row: dict, design: dict) -> None:
    """The row's predictions: default kinematics, and drive-model ones (the second
    measurement), each without and with the camera's noise known."""
    row["pred"] = predicted(row, design)
    row["pred_camera"] = predicted(row, design, camera=True)
    row["pred_dm"] = predicted(row, design, kinematics="drive-model")
    row["pred_dm_camera"] = predicted(row, design, camera=True, kinematics="drive-model")


def _ratio_with_true_mu_d(rows: list[dict], camera: bool = False) -> np.ndarray:
    """Measured / predicted width with the width model told each run's true mu_d / mu."""
    out = []
    for r in rows:
        p = predicted(r, r["design"], camera=camera, true_mu_d=True)
        out.append(r["relative_width"] / p["expected"] if p["expected"] else math.inf)
    return np.array(out)


def finite(r: dict) -> bool:
    return r.get("mu_low") is not None and r.get("mu_high") is not None


def covered(r: dict) -> bool:
    lo, hi = r.get("mu_low"), r.get("mu_high")
    return (lo is None or lo <= r["mu"]) and (hi is None or r["mu"] <= hi)


def report(rows: list[dict], label: str) -> None:
    """Print the figures of one slice of runs."""
    ok = [r for r in rows if r.get("exit") == 0]
    fin = [r for r in ok if finite(r)]
    ratio = np.array([r["relative_width"] / r["pred"]["expected"] for r in fin])
    ratio_cam = np.array([r["relative_width"] / r["pred_camera"]["expected"] for r in fin])
    band_cam = (ratio_cam >= RATIO_BAND[0]) & (ratio_cam <= RATIO_BAND[1])
    inside = np.array([r["pred"]["low90"] <= r["relative_width"] <= r["pred"]["high90"]
                       for r in fin])
    band = (ratio >= RATIO_BAND[0]) & (ratio <= RATIO_BAND[1])
    w = np.array([r["relative_width"] for r in fin])
    print(f"{label}: {len(rows)} runs, {len(ok)} measured, {len(fin)} with finite bounds "
          f"({100 * len(fin) / max(len(rows), 1):.1f} %), coverage "
          f"{100 * np.mean([covered(r) for r in ok]):.1f} % of the stated 95 %")
    if fin:
        print(f"  measured/predicted width: median {np.median(ratio):.3f}, 5-95 % "
              f"[{np.percentile(ratio, 5):.3f}, {np.percentile(ratio, 95):.3f}], within "
              f"[{RATIO_BAND[0]}, {RATIO_BAND[1]}]: {100 * band.mean():.1f} % (target >= 90 %); "
              f"inside the predicted 90 % range: {100 * inside.mean():.1f} %")
        print(f"  with the camera's noise known: median {np.median(ratio_cam):.3f}, 5-95 % "
              f"[{np.percentile(ratio_cam, 5):.3f}, {np.percentile(ratio_cam, 95):.3f}], "
              f"within [{RATIO_BAND[0]}, {RATIO_BAND[1]}]: {100 * band_cam.mean():.1f} %")
        for what, cam in (("", False), (" and the camera's noise", True)):
            known = _ratio_with_true_mu_d(fin, camera=cam)
            kband = (known >= RATIO_BAND[0]) & (known <= RATIO_BAND[1])
            print(f"  with the true mu_d / mu{what} known (no plan knows mu_d: the ceiling of "
                  f"one told it by earlier runs): median {np.median(known):.3f}, 5-95 % "
                  f"[{np.percentile(known, 5):.3f}, {np.percentile(known, 95):.3f}], within "
                  f"[{RATIO_BAND[0]}, {RATIO_BAND[1]}]: {100 * kband.mean():.1f} %")
        print(f"  median measured width {100 * np.median(w):.1f} % (report's run 8.7 %), "
              f"predicted median {100 * np.median([r['pred']['expected'] for r in fin]):.1f} %")
        parts = np.array([[(r["profile_mu_high"] - r["profile_mu_low"]) / r["mu"],
                           2 * (r["pred"]["lens"] or 0.0),
                           2 * max(r["kinematic_rel_bias_at_slip"] - (r["pred"]["lens"] or 0.0),
                                   0.0),
                           (r["lower_bound_sup_z"] + 1.96) * r["kinematic_rel_sigma_at_slip"]]
                          for r in fin])
        med = 100 * np.median(parts, axis=0)
        print(f"  what sets it (medians of abu measure's parts, relative to mu): beta profile "
              f"{med[0]:.1f} %, lens prior 2 A (lever/mu + 2) {med[1]:.1f} %, truncation bound "
              f"x 2 {med[2]:.1f} %, kinematic noise (z_lo + z) sigma {med[3]:.1f} %")
        lens = [r["lens_prior_rad"] for r in fin if r.get("lens_prior_rad") is not None]
        if lens:
            print(f"  calibrated lens prior (--camera) of {len(lens)} runs: median "
                  f"{np.median(lens):.2g} rad, range {min(lens):.2g}-{max(lens):.2g} "
                  "(uncalibrated: 8e-4)")
        prof = np.array([((r["profile_mu_high"] - r["profile_mu_low"]) / r["mu"])
                         / r["pred"]["profile"] for r in fin if r["pred"]["profile"]])
        if prof.size:
            print(f"  beta profile measured / predicted (at mu_d / mu = 0.8): median "
                  f"{np.median(prof):.2f}, 5-95 % [{np.percentile(prof, 5):.2f}, "
                  f"{np.percentile(prof, 95):.2f}]")


def report_second(rows: list[dict], label: str) -> None:
    """The same runs measured with the drive-model kinematics (``--kinematics drive-model``),
    beside the default: refusals and why, finite bounds, coverage, widths; the ratio is
    against the width model for drive-model kinematics (``kinematics="drive-model"``)."""
    ok = [r for r in rows if r.get("exit") == 0 and "drive_model" in r]
    if not ok:
        return
    dm = [{**r["drive_model"], "mu": r["mu"], "pred": r["pred_dm"], "w0": r["relative_width"],
           "pred_cam": r["pred_dm_camera"]} for r in ok]
    failed = [d for d in dm if d["exit"] != 0]
    refused = [d for d in dm if d["exit"] == 0 and d["model"] != "accepted"]
    meas = [d for d in dm if d["exit"] == 0]
    fin = [d for d in meas if finite(d)]
    print(f"  drive-model kinematics, same recordings: {len(meas)} measured "
          f"({len(failed)} failed), model refused in {len(refused)} (the default's kinematics "
          f"kept there), {len(fin)} with finite bounds "
          f"({100 * len(fin) / max(len(dm), 1):.1f} %), coverage "
          f"{100 * np.mean([covered(d) for d in meas]) if meas else math.nan:.1f} %")
    for d in refused + failed:
        print(f"    refused: {d.get('why') or d.get('error')}")
    if not fin:
        return
    w = np.array([d["relative_width"] for d in fin])
    ratio = np.array([d["relative_width"] / d["pred"]["expected"] for d in fin])
    band = (ratio >= RATIO_BAND[0]) & (ratio <= RATIO_BAND[1])
    pair = np.array([d["relative_width"] / d["w0"] for d in fin if d["w0"]])
    acc = [d for d in fin if d["model"] == "accepted"]
    print(f"    median measured width {100 * np.median(w):.1f} % (default "
          f"{100 * np.median([d['w0'] for d in fin if d['w0']]):.1f} %), drive-model / default "
          f"on the same run: median {np.median(pair):.3f}, 5-95 % "
          f"[{np.percentile(pair, 5):.3f}, {np.percentile(pair, 95):.3f}]")
    inside = np.mean([d["pred"]["low90"] <= d["relative_width"] <= d["pred"]["high90"]
                      for d in fin])
    ratio_cam = np.array([d["relative_width"] / d["pred_cam"]["expected"] for d in fin])
    band_cam = (ratio_cam >= RATIO_BAND[0]) & (ratio_cam <= RATIO_BAND[1])
    print(f"    measured / predicted (the width model for drive-model kinematics): median "
          f"{np.median(ratio):.3f}, 5-95 % [{np.percentile(ratio, 5):.3f}, "
          f"{np.percentile(ratio, 95):.3f}], within [{RATIO_BAND[0]}, {RATIO_BAND[1]}]: "
          f"{100 * band.mean():.1f} %, inside the predicted 90 % range {100 * inside:.1f} %; "
          f"with the camera's noise known: median {np.median(ratio_cam):.3f}, within the band "
          f"{100 * band_cam.mean():.1f} %")
    ex = [(d["relative_width"], d["w0"], r["exact"]["relative_width"])
          for d, r in zip(dm, ok) if finite(d) and d["w0"] and (r.get("exact") or {}).get(
              "relative_width")]
    if ex:
        e = np.array(ex)
        print(f"    exact kinematics on the same recordings ({len(ex)}): median width "
              f"{100 * np.median(e[:, 2]):.1f} %; width / exact: drive model median "
              f"{np.median(e[:, 0] / e[:, 2]):.3f}, default {np.median(e[:, 1] / e[:, 2]):.3f}")
    if acc:
        parts = 100 * np.median([[(d["profile_mu_high"] - d["profile_mu_low"]) / d["mu"],
                                  (d["lower_bound_sup_z"] + 1.96)
                                  * d["kinematic_rel_sigma_at_slip"]] for d in acc], axis=0)
        print(f"    accepted runs ({len(acc)}): beta profile {parts[0]:.1f} %, kinematic noise "
              f"(z_lo + z) sigma {parts[1]:.1f} % (medians, relative to mu)")


def calibrate(rows: list[dict]) -> None:
    """Fit the width model's free constants on measured rows (the calibration slice) and print
    them: sigma_beta and sigma_theta are the medians of what ``abu measure`` reported (beta:
    white and leftover in quadrature), z_low the median Rice quantile it used, k_emerge makes
    the median of ln(measured / predicted) zero (bisection), the 90 % range's factors leave 5 %
    of the runs below the smallest and 5 % above the largest width over mu_d / mu."""
    from dataclasses import replace as dc_replace

    from harness.planning.design_width import predict_run_width
    from harness.planning.width_model import CALIBRATED

    fin = [r for r in rows if r.get("exit") == 0 and finite(r)]
    base = dc_replace(
        CALIBRATED, sigma_beta_rad=float(np.median([math.hypot(
            r["sigma_white_beta_rad"] or 0.0, r["sigma_leftover_rad"] or 0.0) for r in fin])),
        sigma_theta_rad=float(np.median([r["sigma_theta_rad"] for r in fin])),
        z_low=float(np.median([r["lower_bound_sup_z"] for r in fin])),
        range_log_low=0.0, range_log_high=0.0)

    def preds(k: float) -> list[dict]:
        c = dc_replace(base, k_emerge=k)
        return [predict_run_width(r["design"], DRIVES[r["drive"]], r["mu"], constants=c)
                for r in fin]

    def log_ratio(ps: list[dict], key: str) -> np.ndarray:
        return np.array([math.log(r["relative_width"] / p[key]) for r, p in zip(fin, ps)])

    lo, hi = 1e-3, 30.0
    for _ in range(16):   # bisection on the median log ratio (it falls as k grows)
        mid = math.sqrt(lo * hi)
        lo, hi = (mid, hi) if np.median(log_ratio(preds(mid), "expected")) > 0 else (lo, mid)
    k = math.sqrt(lo * hi)
    ps = preds(k)
    res = log_ratio(ps, "expected")
    r_lo = float(np.percentile(log_ratio(ps, "low90"), 5))
    r_hi = float(np.percentile(log_ratio(ps, "high90"), 95))
    print(f"calibration on {len(fin)} runs: sigma_beta_rad {base.sigma_beta_rad:.4g}, "
          f"sigma_theta_rad {base.sigma_theta_rad:.4g}, z_low {base.z_low:.4g}, k_emerge "
          f"{k:.4g}, range_log_low {r_lo:.4g}, range_log_high {r_hi:.4g}; measured/predicted "
          "within [0.77, 1.3]: "
          f"{100 * np.mean((res >= math.log(0.77)) & (res <= math.log(1.3))):.1f} %")


def what_if_settings(error_rel: float | None, max_evaluations: int | None) -> None:
    """Every drive-model fit of the in-process ``abu measure`` with these settings."""
    from dataclasses import replace as dc_replace

    from measurement.kinematics import drive_model as dm
    changes = {k: v for k, v in (("error_rel", error_rel), ("max_evaluations", max_evaluations))
               if v is not None}

    def fit(self, time, theta, sigma_theta):
        return dm.fit_drive_model(time, theta, self.drive, self.setpoints,
                                  sigma_theta=sigma_theta,
                                  settings=dc_replace(self.settings, **changes))
    dm.DriveModelInput.fit = fit


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--first", type=int, default=1000, help="first seed")
    ap.add_argument("--runs", type=positive_int, default=72, help="rendered runs in all")
    ap.add_argument("--jobs", type=int, default=1, help="worker processes")
    ap.add_argument("--rows", default=None, help="write the rows as JSON lines here")
    ap.add_argument("--design-args", default="", help="extra options of abu design")
    ap.add_argument("--calibrate", default=None, help="fit the width model's constants on the "
                                                      "rows of this file and exit")
    ap.add_argument("--report", default=None, help="print the figures of the rows of this file "
                                                   "(predicted with the current constants)")
    ap.add_argument("--no-edge-step", action="store_true",
                    help="measure with 'abu measure --no-edge-step' (the contour fits alone, "
                         "as when the width model was calibrated)")
    ap.add_argument("--kinematics", choices=["drive-model"], default=None,
                    help="measure each recording a second time with 'abu measure --kinematics "
                         "drive-model' (the design's drive and staircase) and print it beside")
    ap.add_argument("--free-setpoint-weight", action="store_true",
                    help="with --kinematics drive-model: declare a pi-lag drive as "
                         "pi-lag-weighted (setpoint weight fitted, starting from 1)")
    ap.add_argument("--timing-samples", type=float, default=None,
                    help="with --kinematics drive-model: the drive model's timing bar looks "
                         "this many controller samples either side (what-if; the module's "
                         "TIMING_SAMPLES, 1)")
    ap.add_argument("--error-rel", type=float, default=None,
                    help="with --kinematics drive-model: the fit's discrepancy floor on "
                         "omega_dot (what-if; DriveModelSettings.error_rel, 0.01)")
    ap.add_argument("--max-evaluations", type=int, default=None,
                    help="with --kinematics drive-model: the fit's most model evaluations "
                         "(what-if; DriveModelSettings.max_evaluations, 200)")
    ap.add_argument("--camera", type=int, default=0, metavar="VIEWS",
                    help="calibrate each run's lens on this many chessboard views "
                         "(lens_calibration.calibrate) and measure with 'abu measure --camera' "
                         "(both measurements); the predictions take the calibration's lens prior")
    ap.add_argument("--exact", action="store_true",
                    help="with --kinematics drive-model: measure a third time with the "
                         "plant's exact kinematics (the floor) and print the ratios to it")
    ap.add_argument("--ideal-ball", action="store_true",
                    help="also analyse each run's tracks with the ball at its true centre plus "
                         "the tracker's white noise, with the measured and the exact "
                         "kinematics (what a clean beta would give)")
    ap.add_argument("--zoom", type=float, default=None, metavar="Z",
                    help="film every run Z times closer (twin.scenario.magnified; frames "
                         "Z x 256 px wide): what a sharper ball track gives")
    a = ap.parse_args()
    IDEAL_BALL["on"] = a.ideal_ball
    if a.zoom:
        ZOOM.append(a.zoom)
    DRIVE_MODEL_WHAT_IF["free_setpoint_weight"] = a.free_setpoint_weight
    DRIVE_MODEL_WHAT_IF["exact"] = a.exact
    if a.camera:
        CAMERA_VIEWS.append(a.camera)
    if a.error_rel is not None or a.max_evaluations is not None:
        what_if_settings(a.error_rel, a.max_evaluations)
    if a.timing_samples is not None:   # in-process abu measure: the module's constant
        from measurement.kinematics import drive_model
        drive_model.TIMING_SAMPLES = a.timing_samples
    if a.no_edge_step:   # before the worker pool forks
        EXTRA_MEASURE_ARGS.append("--no-edge-step")
    if a.kinematics:
        SECOND_KINEMATICS.append(a.kinematics)
    if a.calibrate:
        calibrate([json.loads(x) for x in Path(a.calibrate).read_text().splitlines() if x])
        return
    if a.report:   # figures of saved rows, predicted again with the current constants
        rows = [json.loads(x) for x in Path(a.report).read_text().splitlines() if x]
        for r in rows:
            if r.get("exit") == 0:
                add_predictions(r, r["design"])
        print(f"rows of {a.report}: seeds {min(r['seed'] for r in rows)}.."
              f"{max(r['seed'] for r in rows)}")
        report_slices(rows)
        return
    t_wall, t_cpu = time.perf_counter(), time.process_time()
    cfg = configs()
    designs = {c: run_design(*c, a.design_args.split()) for c in cfg}
    for (rng, dname), d in designs.items():
        w = d.get("width_prediction", {})
        print(f"design {dname:16s} [{rng[0]:g}, {rng[1]:g}]: omega0 {d['omega0_hz']} Hz -> "
              f"{d['omega_end_hz']:g} Hz, t0 {d['t0_s']:g} s, te {d['te_s']:.3g} s, "
              f"{d['frames']} frames; predicted width expected "
              f"{100 * w.get('expected', math.nan):.1f} % (90 %: "
              f"{100 * w.get('low90', math.nan):.1f}-{100 * w.get('high90', math.nan):.1f} %)")
    jobs = [(s, *cfg[(s - a.first) % len(cfg)], designs[cfg[(s - a.first) % len(cfg)]])
            for s in range(a.first, a.first + a.runs)]
    if a.jobs > 1:
        pool = Pool(a.jobs)
        rows = pool.map(one, jobs, chunksize=1)
        pool.close()
        pool.join()
    else:
        rows = [one(j) for j in jobs]
    if a.rows:
        Path(a.rows).write_text("".join(json.dumps(r) + "\n" for r in rows))
    for r, j in zip(rows, jobs):
        if r.get("exit") == 0:
            add_predictions(r, j[3])
    print(f"seeds {a.first}..{a.first + a.runs - 1}, {len(cfg)} designs (ranges "
          f"{', '.join(f'[{lo:g}, {hi:g}]' for lo, hi in RANGES)} x drives "
          f"{', '.join(DRIVES)}), true mu log-uniform in each range, mu_d/mu in {MU_D_RATIO}, "
          "lighting and lens of twin.scenario.random_scenario(seed)")
    report_slices(rows)
    print(f"{len(rows)} runs: {time.perf_counter() - t_wall:.0f} s wall, "
          f"{time.process_time() - t_cpu:.0f} s CPU in this process "
          f"({'its worker processes not counted' if a.jobs > 1 else 'one process'})")


def report_slices(rows: list[dict]) -> None:
    """The figures per drive, per prior range, and of all runs."""
    for dname in DRIVES:
        report([r for r in rows if r["drive"] == dname], f"drive {dname}")
        report_second([r for r in rows if r["drive"] == dname], f"drive {dname}")
    for lo, hi in RANGES:
        report([r for r in rows if tuple(r["mu_range"]) == (lo, hi)], f"range [{lo:g}, {hi:g}]")
    report(rows, "all runs")
    report_second(rows, "all runs")
    if any("ideal" in r for r in rows):
        report_ideal(rows)


def report_ideal(rows: list[dict]) -> None:
    """``--ideal-ball``: the width with beta as a perfect lighting model leaves it and with
    the exact kinematics, per drive and overall (medians over the runs measured)."""
    print("what a clean beta and exact kinematics would give (tracks level, the run's camera; "
          "'tracked' should equal abu measure's):")
    names = ("tracked", "tracked_exact", "ideal", "ideal_exact")
    for dname in [*DRIVES, None]:
        sub = [r["ideal"] for r in rows if "ideal" in r and dname in (None, r["drive"])]
        if not sub:
            continue
        med = {n: 100 * np.nanmedian([x[n] for x in sub]) for n in names}
        cov = {n: 100 * np.mean([x[n + "_covers"] for x in sub]) for n in names}
        left = np.median([x["ball_leftover_px"] / x["ball_white_px"] for x in sub])
        print(f"  {dname or 'all runs':16s} n {len(sub):3d}: " + ", ".join(
            f"{n} {med[n]:.1f} % (cov {cov[n]:.0f} %)" for n in names)
            + f"; ball leftover / white {left:.1f}x")


if __name__ == "__main__":
    main()
