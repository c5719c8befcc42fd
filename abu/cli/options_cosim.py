"""Options shared by the co-simulation commands (``simulate``, ``sweep``, ``export-ssp``):
the plant, the speed controller and the staircase, and the experiments they describe.

Speeds are typed in Hz (options ending ``-hz``) and converted to rad/s here, once.
"""
from __future__ import annotations

import argparse
import math

from abu_model.errors import ParameterError
from abu_model.params import BallParams, DEFAULT_J_ABU, PlantParams

HZ = 2.0 * math.pi

#: Library parameter name -> command-line option (for error messages).
OPTION_OF = {"te": "--te", "t0": "--t0", "t_end": "--t-end", "comm_step": "--comm-step",
             "tol": "--tol",
             "zeta": "--zeta", "omega_n": "--omega-n", "mu": "--mu", "mu_d": "--mu-d",
             "m": "--m", "d": "--d", "l": "--l", "J_abu": "--j-abu", "tau_motor": "--tau-motor",
             "beta0": "--beta0", "jerk": "--jerk", "rounding": "--rounding",
             "theta_ref_mode": "--theta-ref", "t_step": "--t-step", "step_hz": "--step-hz"}

def finite(option: str, value: float) -> float:
    if not math.isfinite(value):
        raise ParameterError(option, value, "a finite number")
    return value


def plant_from_args(args: argparse.Namespace) -> PlantParams:
    ball = BallParams(m=args.m, d=args.d, l=args.l, mu=args.mu, mu_d=args.mu_d)
    return PlantParams(ball, J_abu=args.j_abu, tau_motor=args.tau_motor,
                       ball_reaction=args.ball_reaction)


def renamed(exc: ParameterError) -> ParameterError:
    """The same error naming the command-line option."""
    option = OPTION_OF.get(exc.parameter)
    return exc if option is None else ParameterError(option, exc.value, exc.expected)


def add_plant_options(p: argparse.ArgumentParser) -> None:
    b = BallParams()
    g = p.add_argument_group("plant (SI units)")
    g.add_argument("--mu", type=float, default=b.mu,
                   help=f"static friction coefficient [-] (default {b.mu:g})")
    g.add_argument("--mu-d", type=float, default=None,
                   help="sliding friction coefficient [-] (default: mu)")
    g.add_argument("--m", type=float, default=b.m, help=f"ball mass [kg] (default {b.m:g})")
    g.add_argument("--d", type=float, default=b.d, help=f"ball diameter [m] (default {b.d:g})")
    g.add_argument("--l", type=float, default=b.l,
                   help=f"radius of the ball centre's path [m] (default {b.l:g})")
    g.add_argument("--j-abu", type=float, default=DEFAULT_J_ABU,
                   help=f"rotor inertia [kg m^2] (default {DEFAULT_J_ABU:g})")
    g.add_argument("--tau-motor", type=float, default=0.0,
                   help="motor torque lag time constant [s] (default 0: none)")
    g.add_argument("--ball-reaction", action="store_true",
                   help="let the ball's reaction act on the rotor")
    g.add_argument("--beta0", type=float, default=0.0,
                   help="initial ball angle relative to the ABU [rad]")


def add_controller_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("speed controller")
    g.add_argument("--theta-ref", choices=["integral", "thesis"], default="integral",
                   help="theta_ref reading: integral of the setpoint (default) or the report's "
                        "t*w_ref")
    g.add_argument("--zeta", type=float, default=0.5,
                   help="closed-loop damping ratio [-] (default 0.5)")
    g.add_argument("--omega-n", type=float, default=2.2,
                   help="closed-loop natural frequency [rad/s] (default 2.2)")


def add_staircase_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("staircase")
    g.add_argument("--omega0-hz", type=float, default=-17.0,
                   help="initial speed [Hz] (default -17)")
    g.add_argument("--omega-end-hz", type=float, default=-22.0,
                   help="end of the inclined sine [Hz] (default -22)")
    g.add_argument("--t0", type=float, default=0.0,
                   help="start of the inclined sine [s] (default 0)")
    g.add_argument("--te", type=float, default=1.0,
                   help="duration of the inclined sine [s] (default 1)")
    g.add_argument("--t-end", type=float, default=None,
                   help="end of the simulation [s] (default: t0 + te + 0.5; ramp: 1)")
    g.add_argument("--step-hz", type=float, default=1.0,
                   help="setpoint resolution [Hz] (default 1)")
    g.add_argument("--rounding", choices=["lead", "nearest", "trail"], default="lead",
                   help="when each step happens on the sine (default lead: the report's)")


def staircase_from_args(args: argparse.Namespace):
    """The :class:`~harness.experiments.staircase.StaircaseExperiment` the options describe."""
    from harness.experiments.staircase import StaircaseExperiment

    w0 = finite("--omega0-hz", args.omega0_hz)
    we = finite("--omega-end-hz", args.omega_end_hz)
    step = finite("--step-hz", args.step_hz)
    if step <= 0:
        raise ParameterError("--step-hz", step, "a setpoint step > 0 Hz")
    if w0 == 0:
        raise ParameterError("--omega0-hz", w0, "a non-zero speed [Hz] (no normal force at rest)")
    if math.floor(abs(we - w0) / step + 1e-9) < 1:
        raise ParameterError("--omega-end-hz", we, f"a speed at least --step-hz = {step:g} Hz "
                             f"away from --omega0-hz = {w0:g} Hz (the staircase has no step)")
    try:
        return StaircaseExperiment(
            plant_from_args(args), w0 * HZ, we * HZ, t0=args.t0, te=args.te, t_end=args.t_end,
            step=step * HZ, rounding=args.rounding, theta_ref_mode=args.theta_ref,
            zeta=args.zeta, omega_n=args.omega_n, comm_step=args.comm_step, beta0=args.beta0,
            tol=args.tol)
    except ParameterError as exc:
        raise renamed(exc) from None


def ramp_from_args(args: argparse.Namespace):
    """The :class:`~harness.experiments.staircase.RampExperiment` the options describe."""
    from harness.experiments.staircase import RampExperiment

    w0 = finite("--omega0-hz", args.omega0_hz)
    if w0 == 0:
        raise ParameterError("--omega0-hz", w0, "a non-zero speed [Hz]")
    try:
        return RampExperiment(plant_from_args(args), w0 * HZ, args.jerk,
                              1.0 if args.t_end is None else args.t_end,
                              comm_step=args.comm_step, beta0=args.beta0, tol=args.tol)
    except ParameterError as exc:
        raise renamed(exc) from None




def staircase_defaults() -> argparse.Namespace:
    """Every staircase, controller and plant option at its default (what ``simulate`` would
    get with none given)."""
    p = argparse.ArgumentParser(add_help=False)
    add_staircase_options(p)
    add_controller_options(p)
    add_plant_options(p)
    defaults = p.parse_args([])
    defaults.comm_step = defaults.tol = None
    return defaults
