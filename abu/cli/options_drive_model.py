"""``abu measure --kinematics drive-model``: the reference the recorded drive followed.

The drive itself is ``--drive drive.json`` (``abu identify``). A PI drive followed a staircase,
given as in ``abu simulate`` (``--omega0-hz --omega-end-hz --t0 --te --step-hz --rounding``);
a ``tracking`` drive followed a prescribed profile, ``--profile profile.json`` (``abu
design``). Times are on the recording's clock (the fit adds a time offset within +- 50 ms for
the camera's trigger). Without ``--drive`` the loop is unknown and fitted freely from the
record (:mod:`measurement.kinematics.unknown_loop`); a staircase's controller sample time is
then ``--controller-sample-time`` (seconds, or ``continuous``), or, left out, found from the
record among candidates (:mod:`measurement.kinematics.sample_time_search`). With
``--find-staircase`` the staircase itself is found from the record as well
(:mod:`measurement.kinematics.staircase_search`).
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
                        "below or the --profile (without --drive: the loop fitted freely "
                        "from the record); the estimator's where the fit is refused "
                        "(summary.json estimator.model says which and why)")
    p.add_argument("--profile", default=None,
                   help="profile.json ('abu design' for a tracking drive): the prescribed speed "
                        "profile the --drive (model tracking) followed; with --kinematics "
                        "drive-model, instead of the staircase options")
    p.add_argument("--find-staircase", action="store_true",
                   help="with --kinematics drive-model and without --drive: the staircase the "
                        "drive followed (the report's inclined sine in steps of --step-hz) "
                        "found from the record, its start, duration, span and rounding fitted "
                        "with the loop (1-30 s of CPU, ~3 s typical; at most 100 steps), "
                        "instead of the staircase options "
                        "(summary.json estimator.loop names the staircase found)")
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
    g.add_argument("--controller-sample-time", type=_sample_time_arg, default=None,
                   metavar="S", help="without --drive: the digital speed controller's sample "
                   "time [s], or 'continuous' for an analogue one (default: found from the "
                   "record among continuous, the frame interval and 1-10 kHz; summary.json "
                   "estimator.loop names the one found)")


def _sample_time_arg(text: str) -> float | str:
    """``--controller-sample-time``: a number of seconds or the word ``continuous`` (its
    range is checked with the staircase, :func:`_unknown_loop_input`)."""
    if text.strip().lower() == "continuous":
        return "continuous"
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"a sample time [s] or 'continuous', not {text!r}") from None


def drive_model_from_args(args: argparse.Namespace):
    """The analysis's drive-model input (None with ``--kinematics savgol``): a
    ``DriveModelInput`` or ``ProfileModelInput`` with ``--drive``, an ``UnknownLoopInput``
    without; raises ParameterError naming the option."""
    find = getattr(args, "find_staircase", False)
    if args.kinematics != "drive-model":
        if find:
            raise ParameterError("--find-staircase", True, "--kinematics drive-model with it "
                                 "(the staircase is found for the drive model's fit)")
        return None
    from controller.drive import load_drive
    from measurement.kinematics.drive_model import DriveModelInput

    if find:
        return _found_staircase_input(args)
    if not args.drive:
        return _unknown_loop_input(args)
    drive = load_drive(args.drive)
    if args.profile or drive.is_tracking:
        return _profile_input(args, drive)
    setpoints = _staircase(args)
    gaps = [b - a for a, b in zip(setpoints.step_times, setpoints.step_times[1:])]
    if drive.sample_time is not None and gaps and min(gaps) <= drive.sample_time:
        # the model has the controller put each step on a sample of its own
        raise ParameterError("--drive", args.drive, f"a drive whose sample_time_s "
                             f"({drive.sample_time:g} s) is below the staircase's shortest "
                             f"step spacing ({min(gaps):.3g} s): steps would share a sample")
    return DriveModelInput(drive, setpoints)


def _staircase(args: argparse.Namespace):
    """The staircase of the options, each bad one named."""
    from abu_model.loop_response import as_setpoints
    from controller.reference import Staircase

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
    return as_setpoints(Staircase(args.omega0_hz * HZ, args.omega_end_hz * HZ, args.t0,
                                  args.te, step=args.step_hz * HZ, rounding=args.rounding))


def _found_staircase_input(args: argparse.Namespace):
    """``--find-staircase``: the staircase and the loop found from the record; what it
    replaces or cannot use is refused by name."""
    from measurement.kinematics.staircase_search import FIND, FoundStaircaseInput

    for opt, value in (("--drive", args.drive), ("--profile", args.profile),
                       ("--omega0-hz", args.omega0_hz), ("--omega-end-hz", args.omega_end_hz),
                       ("--te", args.te)):
        if value is not None:
            raise ParameterError(opt, value, "left out with --find-staircase (the staircase "
                                 "and the loop are found from the record; state the staircase "
                                 "instead to have it used as given)")
    if not (math.isfinite(args.step_hz) and args.step_hz > 0):
        raise ParameterError("--step-hz", args.step_hz, "a finite setpoint step > 0 Hz")
    sample_time = args.controller_sample_time
    if sample_time == "continuous":
        sample_time = None
    elif sample_time is None:
        sample_time = FIND
    elif not (math.isfinite(sample_time) and 0 < sample_time <= 0.1):
        raise ParameterError("--controller-sample-time", sample_time,
                             "a sample time in (0, 0.1] s, or 'continuous'")
    return FoundStaircaseInput(step_rad_s=args.step_hz * HZ, sample_time_s=sample_time)


def _unknown_loop_input(args: argparse.Namespace):
    """The staircase or profile with the loop left to the fit (no ``--drive``)."""
    from controller.profile import load_profile
    from measurement.kinematics.unknown_loop import FIND, UnknownLoopInput

    sample_time = args.controller_sample_time
    if not args.profile and args.omega0_hz is None:
        raise ParameterError("--kinematics", "drive-model", "the reference the drive followed "
                             "(the staircase options from --omega0-hz on, or --profile), with "
                             "--drive drive.json ('abu identify') or without (the loop fitted "
                             "from the record)")
    if args.profile:
        return UnknownLoopInput(profile=load_profile(args.profile))
    setpoints = _staircase(args)
    if sample_time is None:      # not stated: found from the record
        return UnknownLoopInput(setpoints=setpoints, sample_time_s=FIND)
    if sample_time == "continuous":
        return UnknownLoopInput(setpoints=setpoints, sample_time_s=None)
    gaps = [b - a for a, b in zip(setpoints.step_times, setpoints.step_times[1:])]
    if not (math.isfinite(sample_time) and 0 < sample_time <= 0.1):
        raise ParameterError("--controller-sample-time", sample_time,
                             "a sample time in (0, 0.1] s, or 'continuous'")
    if gaps and min(gaps) <= sample_time:
        raise ParameterError("--controller-sample-time", sample_time,
                             f"a sample time below the staircase's shortest step spacing "
                             f"({min(gaps):.3g} s): steps would share a sample")
    return UnknownLoopInput(setpoints=setpoints, sample_time_s=sample_time)


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
