"""``abu measure --kinematics drive-model``: the reference the recorded drive followed.

The drive itself is ``--drive drive.json`` (``abu identify``). A PI drive followed a staircase,
given as in ``abu simulate`` (``--omega0-hz --omega-end-hz --t0 --te --step-hz --rounding``);
a ``tracking`` drive followed a prescribed profile, ``--profile profile.json`` (``abu
design``). Times are on the recording's clock (the fit adds a time offset within +- 50 ms for
the camera's trigger).
"""
from __future__ import annotations

import argparse
import math

from abu_model.errors import ParameterError

from abu.cli.options_cosim import HZ


def add_drive_model_options(p: argparse.ArgumentParser) -> None:
    """The ``--kinematics`` choice and the staircase options (no defaults: stated or refused)."""
    p.add_argument("--kinematics", choices=["savgol", "drive-model"], default="savgol",
                   help="omega and omega_dot from the Savitzky-Golay estimator (default) or "
                        "from the --drive loop fitted to the whole record over the staircase "
                        "below (the estimator's where the fit is refused; summary.json "
                        "estimator.model says which and why)")
    p.add_argument("--profile", default=None,
                   help="profile.json ('abu design' for a tracking drive): the prescribed speed "
                        "profile the --drive (model tracking) followed; with --kinematics "
                        "drive-model, instead of the staircase options")
    g = p.add_argument_group("staircase of the drive (with --kinematics drive-model)")
    g.add_argument("--omega0-hz", type=float, default=None, help="initial speed [Hz]")
    g.add_argument("--omega-end-hz", type=float, default=None,
                   help="end of the inclined sine [Hz]")
    g.add_argument("--t0", type=float, default=0.0,
                   help="start of the inclined sine on the recording's clock [s] (default 0)")
    g.add_argument("--te", type=float, default=None, help="duration of the inclined sine [s]")
    g.add_argument("--step-hz", type=float, default=1.0,
                   help="setpoint resolution [Hz] (default 1)")
    g.add_argument("--rounding", choices=["lead", "nearest", "trail"], default="lead",
                   help="when each step happens on the sine (default lead: the report's)")


def drive_model_from_args(args: argparse.Namespace):
    """The analysis's ``DriveModelInput`` (None with ``--kinematics savgol``); raises
    ParameterError naming the option."""
    if args.kinematics != "drive-model":
        return None
    from abu_model.loop_response import as_setpoints
    from controller.drive import load_drive
    from controller.reference import Staircase
    from measurement.kinematics.drive_model import DriveModelInput

    if not args.drive:
        raise ParameterError("--drive", None, "a drive.json ('abu identify') with "
                             "--kinematics drive-model")
    drive = load_drive(args.drive)
    if args.profile or drive.is_tracking:
        return _profile_input(args, drive)
    for opt, value in (("--omega0-hz", args.omega0_hz), ("--omega-end-hz", args.omega_end_hz),
                       ("--te", args.te)):
        if value is None or not math.isfinite(value):
            raise ParameterError(opt, value, "a finite number (the staircase the drive "
                                 "followed) with --kinematics drive-model")
    if args.omega0_hz == 0:
        raise ParameterError("--omega0-hz", args.omega0_hz, "a non-zero speed [Hz]")
    if not (math.isfinite(args.step_hz) and args.step_hz > 0):
        raise ParameterError("--step-hz", args.step_hz, "a finite setpoint step > 0 Hz")
    if not args.te > 0:
        raise ParameterError("--te", args.te, "a duration > 0 s")
    if not math.isfinite(args.t0):
        raise ParameterError("--t0", args.t0, "a finite start time [s]")
    if args.omega_end_hz * args.omega0_hz <= 0:
        raise ParameterError("--omega-end-hz", args.omega_end_hz,
                             "a speed of the same sign as --omega0-hz (the drive turns one way)")
    stair = Staircase(args.omega0_hz * HZ, args.omega_end_hz * HZ, args.t0, args.te,
                      step=args.step_hz * HZ, rounding=args.rounding)
    setpoints = as_setpoints(stair)
    gaps = [b - a for a, b in zip(setpoints.step_times, setpoints.step_times[1:])]
    if drive.sample_time is not None and gaps and min(gaps) <= drive.sample_time:
        # the model has the controller put each step on a sample of its own
        raise ParameterError("--drive", args.drive, f"a drive whose sample_time_s "
                             f"({drive.sample_time:g} s) is below the staircase's shortest "
                             f"step spacing ({min(gaps):.3g} s): steps would share a sample")
    return DriveModelInput(drive, setpoints)


def _profile_input(args: argparse.Namespace, drive):
    """The tracking drive and its profile (``--profile``); each mismatch named."""
    from controller.profile import load_profile
    from measurement.kinematics.profile_model import ProfileModelInput

    if not drive.is_tracking:
        raise ParameterError("--profile", args.profile, f"no profile with a {drive.model} drive "
                             "(it follows a staircase); --drive must be of model 'tracking'")
    if not args.profile:
        raise ParameterError("--profile", None, "the profile.json the tracking drive of --drive "
                             "followed ('abu design --drive ... --out plan' writes one)")
    return ProfileModelInput(drive, load_profile(args.profile))
