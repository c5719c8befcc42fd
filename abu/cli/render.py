"""``abu render``: the camera twin of the report's experiment, or one recording of the harsh
random family (``--scenario random --seed N``, optionally with chessboard views for ``abu
calibrate-camera``), written into a fresh output folder."""
from __future__ import annotations

import argparse
from pathlib import Path

from dataclasses import replace

from abu_model.errors import ParameterError

from abu.cli.checks_measure import check_render_options
from abu.cli.common import add_overwrite, integer_range, log as _log
from abu.cli.output_tx import output_folder
from twin.report_twin import TWO_PI, TwinSettings


def cmd_render(args: argparse.Namespace) -> int:
    """``abu render --out DIR``: render the digital twin of the report's experiment."""
    check_render_options(args)
    if getattr(args, "fmu_dir", None):
        from abu.cli.checks_cosim import check_fmu_dir
        check_fmu_dir("--fmu-dir", args.fmu_dir, ("AbuBall", "SpeedController", "Staircase"))
    out = Path(args.out)
    if getattr(args, "profile", None):
        return _render_tracking(args, out)
    if getattr(args, "scenario", "report") == "random":
        if getattr(args, "drive", None):
            raise ParameterError("--drive", args.drive, "no --drive with --scenario random "
                                 "(its drive is drawn at random)")
        if args.calibration_views:
            from twin.calibration_target import MAX_VIEWS
            from measurement.imaging.camera_calibration import MIN_VIEWS  # fewer: calibrate-camera refuses them
            integer_range("--calibration-views", args.calibration_views, MIN_VIEWS, MAX_VIEWS,
                          "chessboard views for 'abu calibrate-camera'")
        from twin.scenario import random_scenario, render_scenario
        scn = random_scenario(args.seed, size=args.size, lighting=args.lighting,
                              n_frames=args.frames)
        with output_folder(out, overwrite=args.overwrite) as tmp:
            render_scenario(tmp, scn)
            if args.calibration_views:  # chessboard views through the same lens and sensor
                from twin.calibration_target import write_views
                write_views(tmp / "calibration", scn.optics, scn.width, scn.height,
                            args.calibration_views, scn.seed, pixel_size_m=scn.pixel_size)
        _log(args, f"wrote the random twin recording (seed {args.seed}, mu = {scn.ball.mu:.5g}, "
                   f"{scn.drive.kind} drive, {scn.lighting.kind} lighting) to {out}")
        return 0
    if getattr(args, "calibration_views", 0):
        raise ParameterError("--calibration-views", args.calibration_views, "0 with --scenario "
                             "report (its lens is ideal; use --scenario random)")
    from twin.report_twin import render_twin
    from abu.cli.plan import apply_drive_to_args
    apply_drive_to_args(args)
    settings = _twin_settings(args)
    with output_folder(out, overwrite=args.overwrite) as tmp:
        render_twin(tmp, settings, fmu_dir=getattr(args, "fmu_dir", None))
    _log(args, f"wrote the twin recording to {out}")
    return 0


def _render_tracking(args: argparse.Namespace, out: Path) -> int:
    """``--drive tracking.json --profile profile.json --mu MU``: the seed's camera of the harsh
    twin filming the tracking drive (:mod:`twin.tracking_scenario`)."""
    from controller.profile import load_profile
    from twin.scenario import render_scenario
    from twin.tracking_scenario import tracking_scenario, tracking_spec
    from abu.cli.plan import load_drive_option

    if not args.drive:
        raise ParameterError("--drive", None, "a drive.json of model 'tracking' with --profile "
                             "(the loop that follows the profile)")
    drive = load_drive_option(args.drive)
    profile = load_profile(args.profile)
    spec = tracking_spec(drive, profile)
    scn = tracking_scenario(args.seed, spec, args.mu, size=args.size, lighting=args.lighting,
                            n_frames=args.frames, fps=args.fps)
    with output_folder(out, overwrite=args.overwrite) as tmp:
        render_scenario(tmp, scn)
    slip = "no slip predicted" if scn.predicted_slip_s is None else \
        f"slip predicted at {scn.predicted_slip_s:.4g} s"
    _log(args, f"wrote the tracking-drive recording (mu = {args.mu:.5g}, seed {args.seed}, "
               f"{scn.lighting.kind} lighting, {slip}) to {out}")
    return 0


def register(subparsers) -> None:
    """Add ``render`` to the ``abu`` subcommands."""
    p = subparsers.add_parser("render", help="render the digital twin of the experiment",
                              description="Simulate the report's experiment and render it as a "
                                          "high-speed camera recording (frames.tif, truth.csv, "
                                          "meta.json).")
    p.add_argument("--out", required=True, help="output folder")
    add_overwrite(p)
    _add_render_arguments(p)
    p.add_argument("--fmu-dir", default=None,
                   help="folder with the FMUs (built there if missing; default: a "
                        "temporary build)")
    p.add_argument("--drive", default=None, help="drive.json of 'abu identify': its zeta, omega_n "
                   "and tau_motor replace --zeta, --omega-n, --tau-motor")
    p.add_argument("--profile", default=None,
                   help="profile.json ('abu design' with a tracking --drive): render the "
                        "tracking drive following it, filmed by the harsh twin's camera drawn "
                        "from --seed (applies: --mu, --seed, --frames, --fps, --size, "
                        "--lighting)")
    p.add_argument("--quiet", action="store_true", help="no messages on stderr")
    p.set_defaults(func=cmd_render)


def _add_render_arguments(p: argparse.ArgumentParser) -> None:
    """Options of ``abu render`` (Hz only here, in names ending ``-hz``)."""
    d = TwinSettings()
    r = d.render
    g = d.geometry
    p.add_argument("--mu", type=float, default=d.mu, help=f"true static friction coefficient "
                                                          f"(default {d.mu:g})")
    p.add_argument("--omega0-hz", type=float, default=d.omega0 / TWO_PI,
                   help=f"initial speed [Hz] (default {d.omega0 / TWO_PI:g}; negative = clockwise)")
    p.add_argument("--omega-end-hz", type=float, default=d.omega_end / TWO_PI,
                   help=f"final speed [Hz] (default {d.omega_end / TWO_PI:g})")
    p.add_argument("--t0", type=float, default=d.t0, help="start of the staircase [s]")
    p.add_argument("--te", type=float, default=d.te, help="duration of the staircase [s]")
    p.add_argument("--rounding", choices=["lead", "nearest", "trail"], default=d.drive.rounding,
                   help=f"staircase rounding (default {d.drive.rounding}, the report's)")
    p.add_argument("--step-hz", type=float, default=d.drive.step / TWO_PI,
                   help=f"setpoint resolution [Hz] (default {d.drive.step / TWO_PI:g})")
    p.add_argument("--fps", type=float, default=d.fps, help="frame rate [frames/s]")
    p.add_argument("--frames", type=int, default=d.n_frames, help="number of frames")
    p.add_argument("--beta0", type=float, default=d.beta0, help="initial ball angle [rad]")
    p.add_argument("--zeta", type=float, default=d.drive.zeta, help="drive damping ratio")
    p.add_argument("--omega-n", type=float, default=d.drive.omega_n,
                   help="drive natural frequency [rad/s]")
    p.add_argument("--tau-motor", type=float, default=d.drive.tau_motor,
                   help="motor torque lag [s]")
    p.add_argument("--noise", type=float, default=r.noise_sigma,
                   help="sensor noise sigma [grey levels]")
    p.add_argument("--gradient", type=float, default=r.gradient,
                   help="lighting gradient [grey levels/px]")
    p.add_argument("--ball-shift-px", type=float, default=r.ball_shift_px,
                   help="asymmetric-lighting offset of the ball's apparent centre [px]")
    p.add_argument("--exposure-fraction", type=float, default=r.exposure_fraction,
                   help="exposure / frame interval for motion blur (0 = none)")
    p.add_argument("--pixel-size", type=float, default=g.pixel_size, help="pixel size [m/px]")
    p.add_argument("--seed", type=int, default=d.seed,
                   help="noise seed; with --scenario random the seed of every drawn setting")
    p.add_argument("--scenario", choices=["report", "random"], default="report",
                   help="report (default): the report's experiment with the options above; "
                        "random: draw mu, drive, lighting, optics and sensor from --seed (the "
                        "harsh family of twin.scenario; only --seed, --size, --lighting "
                        "and --frames apply)")
    p.add_argument("--size", type=int, default=256,
                   help="--scenario random: frame width = height [px] (>= 200, default 256)")
    p.add_argument("--lighting", choices=["ring", "two_spot"], default=None,
                   help="--scenario random: force the TL ring or the two-spot lighting (two "
                        "reflections on the ball; default: drawn, 25 %% two_spot)")
    p.add_argument("--calibration-views", type=int, default=0,
                   help="--scenario random: also write K chessboard views through the same lens "
                        "and sensor into calibration/ (for 'abu calibrate-camera': 4..100; "
                        "default 0; the benchmark uses 30)")


def _twin_settings(args: argparse.Namespace) -> TwinSettings:
    """TwinSettings from the options of :func:`_add_render_arguments`."""
    d = TwinSettings()
    render = d.render.with_(noise_sigma=args.noise, gradient=args.gradient,
                            ball_shift_px=args.ball_shift_px,
                            exposure_fraction=args.exposure_fraction)
    from abu.cli.common import positive
    drive = replace(d.drive, zeta=args.zeta, omega_n=args.omega_n, tau_motor=args.tau_motor,
                    rounding=args.rounding,
                    step=positive("--step-hz", args.step_hz, "Hz") * TWO_PI)
    return d.with_(mu=args.mu, omega0=args.omega0_hz * TWO_PI,
                   omega_end=args.omega_end_hz * TWO_PI, t0=args.t0, te=args.te, fps=args.fps,
                   n_frames=args.frames, beta0=args.beta0, drive=drive, render=render,
                   geometry=replace(d.geometry, pixel_size=args.pixel_size), seed=args.seed)
