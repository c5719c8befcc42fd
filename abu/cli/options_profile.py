"""``abu simulate --motion profile``: the tracking drive (``--drive``, model tracking) following
``--profile profile.json``, co-simulated on AbuBall (:mod:`harness.experiments.profile_run`)."""
from __future__ import annotations

import argparse

from abu_model.errors import ParameterError

from abu.cli.checks_cosim import check_plant
from abu.cli.common import in_range, positive

#: most communication steps of one run (about 3 ms of computing each with the Python FMUs)
MAX_STEPS = 200_000


def profile_experiment_from_args(args: argparse.Namespace):
    """The :class:`ProfileExperiment` the options describe; each bad one named."""
    from abu_model.params import BallParams, PlantParams
    from controller.drive import load_drive
    from controller.profile import load_profile
    from harness.experiments.profile_run import COMM_STEP, ProfileExperiment

    if not args.drive:
        raise ParameterError("--drive", None, "a drive.json of model 'tracking' with --motion "
                             "profile (the loop that follows the profile)")
    if not args.profile:
        raise ParameterError("--profile", None, "the profile.json the tracking drive follows "
                             "with --motion profile ('abu design --drive ... --out plan')")
    drive = load_drive(args.drive)
    if not drive.is_tracking:
        raise ParameterError("--drive", args.drive, f"a drive of model 'tracking' with --motion "
                             f"profile (this one is {drive.model}: it follows a staircase)")
    profile = load_profile(args.profile)
    args.tau_motor = drive.tau_motor
    check_plant(args)
    h = COMM_STEP if args.comm_step is None else positive("--comm-step", args.comm_step, "s")
    in_range("--comm-step", h, 1e-7, 0.01, "s", "a communication step the torque's Taylor "
             "hold follows")
    start = min(0.0, profile.times[0] - 0.05)
    stop = profile.times[-1] + 0.05 if args.t_end is None else args.t_end
    if (stop - start) / h > MAX_STEPS:
        raise ParameterError("--comm-step", h, f"at most {MAX_STEPS} communication steps over "
                             f"the run ({stop - start:.3g} s)")
    ball = BallParams(m=args.m, d=args.d, l=args.l, mu=args.mu, mu_d=args.mu_d)
    plant = PlantParams(ball, J_abu=args.j_abu, tau_motor=drive.tau_motor,
                        ball_reaction=args.ball_reaction)
    return ProfileExperiment(plant, drive, profile, t_end=args.t_end, comm_step=h,
                             beta0=args.beta0)
