"""Options that the chosen mode ignores are refused, naming the option and why (issue 19).

A user who types ``abu render --scenario random --seed 7 --mu 0.02`` expects mu = 0.02; the
random scenario draws mu from the seed. Rather than drop such an option silently, every command
refuses an option given explicitly (:func:`abu.cli.common.given`: typed on the command line, in
any spelling, even with its default value) that its mode does not use. The rules, one table for
all commands: (command, condition on the parsed options, options it rules out, why).

The sweep's options are checked by its own module (``abu sweep``'s engine).
"""
from __future__ import annotations

import argparse
from typing import Callable

from abu.cli.common import refuse_given

Rule = tuple[str, Callable[[argparse.Namespace], bool], tuple[str, ...], str]

_STAIRCASE = ("--omega-end-hz", "--t0", "--te", "--step-hz", "--rounding")
_TRACKING = ("--seeds", "--dark-markers", "--method", "--window", "--ball-reflections",
             "--ball-method", "--progress", "--edge-step", "--no-edge-step")
_DRIVE_SETS = ("--zeta", "--omega-n", "--tau-motor")
#: Options of the render's report scenario that --scenario random draws from --seed.
RENDER_REPORT_ONLY = ("--mu", "--omega0-hz", "--omega-end-hz", "--t0", "--te", "--fps",
                      "--beta0", "--zeta", "--omega-n", "--tau-motor", "--noise", "--gradient",
                      "--ball-shift-px", "--exposure-fraction", "--pixel-size", "--fmu-dir",
                      "--drive")


def _no_out(args: argparse.Namespace) -> bool:
    return not getattr(args, "out", None)


RULES: tuple[Rule, ...] = (
    # simulate
    ("simulate", lambda a: a.motion == "ramp", _STAIRCASE + ("--theta-ref", "--zeta", "--omega-n",
                                                            "--drive"),
     "with --motion ramp (the ramp prescribes the torque: no staircase, no speed controller)"),
    ("simulate", lambda a: a.motion == "staircase", ("--jerk",),
     "with --motion staircase (--jerk is the ramp's; use --motion ramp)"),
    ("simulate", lambda a: a.motion != "profile", ("--profile",),
     "without --motion profile (the profile is the tracking drive's reference)"),
    ("simulate", lambda a: a.motion == "profile", _STAIRCASE + (
        "--omega0-hz", "--theta-ref", "--zeta", "--omega-n", "--jerk", "--tol", "--tau-motor"),
     "with --motion profile (the drive.json and profile.json set the motion; the tracking "
     "loop is modelled exactly at fixed communication steps)"),
    ("simulate", lambda a: bool(a.drive) and a.motion != "profile", _DRIVE_SETS,
     "with --drive (the drive.json sets zeta, omega_n and tau_motor)"),
    ("simulate", lambda a: a.tol is not None, ("--comm-step",),
     "with --tol (--tol chooses the communication steps by error control; give one of them)"),
    ("simulate", _no_out, ("--overwrite",), "without --out (nothing is written to replace)"),
    # table41
    ("table41", lambda a: a.no_check, ("--fmu-dir",),
     "with --no-check (the FMUs are only used by the co-simulation check)"),
    # render
    ("render", lambda a: a.scenario == "random", RENDER_REPORT_ONLY,
     "with --scenario random: it draws mu, the drive, the lighting, the optics and the sensor "
     "from --seed (only --seed, --size, --lighting, --frames and --calibration-views apply)"),
    ("render", lambda a: bool(a.profile), ("--omega0-hz", "--omega-end-hz", "--t0", "--te",
                                           "--beta0", "--zeta", "--omega-n", "--tau-motor",
                                           "--noise", "--gradient", "--ball-shift-px",
                                           "--exposure-fraction", "--pixel-size", "--fmu-dir",
                                           "--scenario", "--calibration-views"),
     "with --profile (the tracking drive follows the profile; the camera is drawn from --seed: "
     "only --mu, --seed, --frames, --fps, --size and --lighting apply)"),
    ("render", lambda a: a.scenario == "report" and not a.profile, ("--size", "--lighting"),
     "with --scenario report (only --scenario random draws the frame size and the lighting)"),
    ("render", lambda a: a.scenario == "report" and bool(a.drive), _DRIVE_SETS,
     "with --drive (the drive.json sets zeta, omega_n and tau_motor)"),
    # track, measure
    ("track", lambda a: a.ball_reflections == 1, ("--ball-method",),
     "with --ball-reflections 1 (the ball method chooses between two reflections)"),
    # with --tracks, --ball-reflections still says how the tracked ball looked (it chooses the
    # default lighting models); the other tracking options only set up the tracker
    ("measure", lambda a: a.tracks, tuple(o for o in _TRACKING if o != "--ball-reflections"),
     "with --tracks (the markers are already tracked; these options set up the tracker)"),
    ("measure", lambda a: not a.tracks and a.ball_reflections == 1, ("--ball-method",),
     "with --ball-reflections 1 (the ball method chooses between two reflections)"),
    ("measure", lambda a: a.estimator == "savgol", ("--poly-degree",),
     "with --estimator savgol (the polynomial degree is the report estimator's)"),
    ("measure", lambda a: a.no_harmonic, ("--harmonic-phase", "--lighting-models"),
     "with --no-harmonic (no lighting harmonic is fitted)"),
    ("measure", lambda a: a.mc_draws == 0, ("--seed",),
     "with --mc-draws 0 (the seed draws the Monte Carlo noise; give --mc-draws N)"),
    ("measure", lambda a: a.kinematics != "drive-model", _STAIRCASE + ("--omega0-hz",
                                                                       "--profile"),
     "without --kinematics drive-model (the staircase or profile serves only the drive "
     "model's fit)"),
    ("measure", lambda a: bool(a.profile), _STAIRCASE + ("--omega0-hz",),
     "with --profile (the tracking drive followed the profile, not a staircase)"),
    ("measure", lambda a: a.kinematics != "drive-model" or bool(a.drive) or bool(a.profile),
     ("--controller-sample-time",),
     "except with --kinematics drive-model over a staircase without --drive (a drive.json "
     "states its own sample_time_s; a profile's tracking loop is continuous)"),
    # identify
    ("identify", lambda a: a.pulses is None, ("--pulses-per-rev",),
     "without --pulses (it counts the pulses of --pulses)"),
    ("identify", lambda a: a.setpoints is not None, _STAIRCASE + ("--omega0-hz",),
     "with --setpoints (the CSV gives the setpoints; the staircase options describe one)"),
    ("identify", _no_out, ("--overwrite", "--no-plots"), "without --out (nothing is written)"),
    # design, next
    ("design", lambda a: a.no_check, ("--fmu-dir",),
     "with --no-check (the FMUs are only used by the co-simulation check)"),
    ("design", _no_out, ("--overwrite", "--no-plots"), "without --out (nothing is written)"),
    ("next", lambda a: a.no_check, ("--fmu-dir",),
     "with --no-check (the FMUs are only used by the co-simulation check)"),
    ("next", _no_out, ("--overwrite", "--no-plots"), "without --out (nothing is written)"),
)


def check_not_applicable(command: str, args: argparse.Namespace) -> None:
    """Refuse the first option given explicitly that ``command``'s chosen mode ignores."""
    for name, applies, options, why in RULES:
        if name == command and applies(args):
            refuse_given(args, options, why)
