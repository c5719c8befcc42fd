"""The ``abu`` command line.

Subcommands: ``build-fmus``, ``simulate`` (its files and text: :mod:`harness.simulate_output`),
``table41``, ``sweep``, ``demo`` (:mod:`harness.cli_demo`) here, and the measurement
commands ``track``, ``measure``, ``measure-summary``, ``render`` (:mod:`measurement.cli`) and
``calibrate-camera`` (:mod:`measurement.cli_camera`).

Speeds are given in Hz on the command line (options ending ``-hz``) and converted to rad/s at
once; everything else is SI. A user error (:class:`abu_model.errors.AbuError`) prints one line
naming the option on stderr and exits with status 2, without a traceback.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path
from typing import Sequence

from abu_model.errors import ParameterError
from abu_model.params import BallParams, DEFAULT_J_ABU, PlantParams

from .cli_checks import (check_fmu_dir, check_ramp, check_staircase, check_sweep,
                         check_table41, check_table41_speeds)
from .cli_common import AbuArgumentParser, add_overwrite, option_error, run_command
from .cli_demo import cmd_demo
from .output_tx import output_file, output_folder
from .simulate_output import describe, tagged_summary, write_outputs  # noqa: F401 (API)

HZ = 2.0 * math.pi

#: Library parameter name -> command-line option (for error messages).
OPTION_OF = {"te": "--te", "t0": "--t0", "t_end": "--t-end", "comm_step": "--comm-step",
             "tol": "--tol",
             "zeta": "--zeta", "omega_n": "--omega-n", "mu": "--mu", "mu_d": "--mu-d",
             "m": "--m", "d": "--d", "l": "--l", "J_abu": "--j-abu", "tau_motor": "--tau-motor",
             "beta0": "--beta0", "jerk": "--jerk", "rounding": "--rounding",
             "theta_ref_mode": "--theta-ref", "t_step": "--t-step", "step_hz": "--step-hz"}

FMU_NAMES = ("AbuBall", "SpeedController", "Staircase")


def _finite(option: str, value: float) -> float:
    if not math.isfinite(value):
        raise ParameterError(option, value, "a finite number")
    return value


def _plant(args: argparse.Namespace) -> PlantParams:
    ball = BallParams(m=args.m, d=args.d, l=args.l, mu=args.mu, mu_d=args.mu_d)
    return PlantParams(ball, J_abu=args.j_abu, tau_motor=args.tau_motor,
                       ball_reaction=args.ball_reaction)


def _renamed(exc: ParameterError) -> ParameterError:
    """The same error naming the command-line option."""
    option = OPTION_OF.get(exc.parameter)
    return exc if option is None else ParameterError(option, exc.value, exc.expected)


def _add_plant_options(p: argparse.ArgumentParser) -> None:
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


def _add_controller_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("speed controller")
    g.add_argument("--theta-ref", choices=["integral", "thesis"], default="integral",
                   help="theta_ref reading: integral of the setpoint (default) or the report's "
                        "t*w_ref")
    g.add_argument("--zeta", type=float, default=0.5,
                   help="closed-loop damping ratio [-] (default 0.5)")
    g.add_argument("--omega-n", type=float, default=2.2,
                   help="closed-loop natural frequency [rad/s] (default 2.2)")


def _add_staircase_options(p: argparse.ArgumentParser) -> None:
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


def build_parser() -> argparse.ArgumentParser:
    """The ``abu`` argument parser with every subcommand."""
    parser = AbuArgumentParser(
        prog="abu", description="Static friction of a ball in an automatic balancing unit: "
                                "FMI co-simulation and high-speed camera measurement.")
    parser.add_argument("--debug", action="store_true",
                        help="show the traceback of an unexpected error (any position)")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("build-fmus", help="build AbuBall.fmu, SpeedController.fmu, Staircase.fmu",
                       description="Build the three FMI 2.0 co-simulation FMUs (pythonfmu).")
    p.add_argument("--out", required=True, help="output folder")
    add_overwrite(p)
    p.set_defaults(func=cmd_build_fmus)

    p = sub.add_parser("simulate", help="co-simulate the staircase or the ramp experiment",
                       description="Co-simulate an experiment of the report (ch. 4) on the FMUs "
                                   "and compute the friction bounds mu_low <= mu < mu_high.")
    p.add_argument("--motion", choices=["staircase", "ramp"], default="staircase",
                   help="staircase of setpoints (sec. 4.2, default) or prescribed acceleration "
                        "ramp (sec. 4.1)")
    _add_staircase_options(p)
    _add_controller_options(p)
    g = p.add_argument_group("ramp")
    g.add_argument("--jerk", type=float, default=3000.0,
                   help="growth rate K of |omega_dot| [rad/s^3] (default 3000)")
    _add_plant_options(p)
    g = p.add_argument_group("run")
    g.add_argument("--comm-step", type=float, default=None,
                   help="fixed communication step [s] (without --tol: fixed-step mode; default: "
                        "error-controlled steps)")
    g.add_argument("--tol", type=float, default=None,
                   help="coupling error tolerance [-] of the error-controlled steps (default "
                        "1e-9: bounds within about 1e-10 relative, switch times within "
                        "1e-9 s; see docs/harness.md)")
    g.add_argument("--fmu-dir", default=None, help="folder with the FMUs (built there if missing; "
                                                   "default: a temporary build)")
    g.add_argument("--out", default=None, help="write result.csv, summary.json and PNG plots here")
    add_overwrite(g)
    g.add_argument("--json", action="store_true", help="print the summary as JSON on stdout")
    g.add_argument("--progress", action="store_true", help="show a progress bar on stderr")
    p.add_argument("--drive", default=None, help="drive.json of 'abu identify': its zeta, "
                   "omega_n and tau_motor replace --zeta, --omega-n, --tau-motor")
    p.set_defaults(func=cmd_simulate)

    p = sub.add_parser("table41", help="smallest |omega0| at which one step keeps the ball stuck",
                       description="Table 4.1 of the report: for each mu, the smallest integer "
                                   "|omega0| [Hz] at which one setpoint step from steady rotation "
                                   "does not make the ball slip (closed form, checked by "
                                   "co-simulation of that value and the one below).")
    p.add_argument("--mu", type=float, nargs="+", required=True, help="friction coefficients [-]")
    p.add_argument("--theta-ref", choices=["integral", "thesis"], default="integral",
                   help="theta_ref reading (default integral)")
    p.add_argument("--t-step", type=float, default=0.0,
                   help="time of the step [s] (thesis mode; default 0)")
    p.add_argument("--step-hz", type=float, default=1.0, help="setpoint step [Hz] (default 1)")
    p.add_argument("--no-check", action="store_true", help="skip the co-simulation check")
    p.add_argument("--fmu-dir", default=None, help="folder with the FMUs (built if missing)")
    p.add_argument("--json", action="store_true", help="print a JSON list on stdout")
    p.set_defaults(func=cmd_table41)

    p = sub.add_parser("demo", help="the report's staircase co-simulation and the measurement "
                                    "chain on a rendered recording",
                       description="Build the FMUs, co-simulate the report's staircase experiment "
                                   "(sec. 4.2.3: mu = 2.75e-3, -17 Hz -> -22 Hz in 1 s) with both "
                                   "theta_ref readings, print the bounds and write plots; then "
                                   "render the synthetic camera twin (sec. 5.3, mu = 0.03), track "
                                   "and measure it.")
    p.add_argument("--out", required=True, help="output folder")
    add_overwrite(p)
    p.set_defaults(func=cmd_demo)

    p = sub.add_parser("sweep", help="staircase co-simulations over a grid of mu and omega0 "
                                     "on a Dask cluster",
                       description="Run the staircase experiment for every (mu, omega0) pair, one "
                                   "co-simulation per worker process (local cluster, or a running "
                                   "Dask scheduler), and write the bounds as CSV.")
    p.add_argument("--mu", type=float, nargs="+", required=True, help="friction coefficients [-]")
    p.add_argument("--omega0-hz", type=float, nargs="+", required=True,
                   help="initial speeds [Hz]; the staircase spans --span-hz from each")
    p.add_argument("--span-hz", type=float, default=-5.0,
                   help="omega_end - omega0 [Hz] (default -5, the report's)")
    p.add_argument("--te", type=float, default=1.0,
                   help="duration of the inclined sine [s] (default 1)")
    p.add_argument("--rounding", choices=["lead", "nearest", "trail"], default="lead")
    _add_controller_options(p)
    p.add_argument("--workers", type=int, default=2, help="local worker processes (default 2)")
    p.add_argument("--scheduler", default=None,
                   help="address of a running Dask scheduler (default: start a local cluster)")
    p.add_argument("--fmu-dir", default=None, help="folder with the FMUs, readable by every worker "
                                                   "(default: built into --out's folder)")
    p.add_argument("--out", required=True, help="CSV file to write")
    add_overwrite(p)
    p.add_argument("--progress", action="store_true", help="show a progress bar on stderr")
    p.set_defaults(func=cmd_sweep)

    from measurement.cli import register
    register(sub)
    from .cli_export import register as register_export
    register_export(sub)
    from .cli_plan import register as register_plan
    register_plan(sub)
    return parser


# ---------------------------------------------------------------------------- commands
def cmd_build_fmus(args: argparse.Namespace) -> int:
    from fmus.build import build_fmus

    out = Path(args.out)
    with output_folder(out, overwrite=args.overwrite) as tmp:
        built = build_fmus(tmp)
    for name, path in built.items():
        print(f"{name}: {out / path.name}")
    return 0


def staircase_from_args(args: argparse.Namespace):
    """The :class:`~harness.experiments.StaircaseExperiment` the options describe."""
    from .experiments import StaircaseExperiment

    w0 = _finite("--omega0-hz", args.omega0_hz)
    we = _finite("--omega-end-hz", args.omega_end_hz)
    step = _finite("--step-hz", args.step_hz)
    if step <= 0:
        raise ParameterError("--step-hz", step, "a setpoint step > 0 Hz")
    if w0 == 0:
        raise ParameterError("--omega0-hz", w0, "a non-zero speed [Hz] (no normal force at rest)")
    if math.floor(abs(we - w0) / step + 1e-9) < 1:
        raise ParameterError("--omega-end-hz", we, f"a speed at least --step-hz = {step:g} Hz "
                             f"away from --omega0-hz = {w0:g} Hz (the staircase has no step)")
    try:
        return StaircaseExperiment(
            _plant(args), w0 * HZ, we * HZ, t0=args.t0, te=args.te, t_end=args.t_end,
            step=step * HZ, rounding=args.rounding, theta_ref_mode=args.theta_ref,
            zeta=args.zeta, omega_n=args.omega_n, comm_step=args.comm_step, beta0=args.beta0,
            tol=args.tol)
    except ParameterError as exc:
        raise _renamed(exc) from None


def ramp_from_args(args: argparse.Namespace):
    """The :class:`~harness.experiments.RampExperiment` the options describe."""
    from .experiments import RampExperiment

    w0 = _finite("--omega0-hz", args.omega0_hz)
    if w0 == 0:
        raise ParameterError("--omega0-hz", w0, "a non-zero speed [Hz]")
    try:
        return RampExperiment(_plant(args), w0 * HZ, args.jerk,
                              1.0 if args.t_end is None else args.t_end,
                              comm_step=args.comm_step, beta0=args.beta0, tol=args.tol)
    except ParameterError as exc:
        raise _renamed(exc) from None


def cmd_simulate(args: argparse.Namespace) -> int:
    from .experiments import run_ramp, run_staircase

    from .cli_plan import apply_drive_to_args
    apply_drive_to_args(args)
    (check_staircase if args.motion == "staircase" else check_ramp)(args)
    check_fmu_dir("--fmu-dir", args.fmu_dir, FMU_NAMES)
    exp = staircase_from_args(args) if args.motion == "staircase" else ramp_from_args(args)
    run = run_staircase if args.motion == "staircase" else run_ramp
    written = []
    if args.out:  # locked and checked before the co-simulation, written at its end
        out = Path(args.out)
        with output_folder(out, overwrite=args.overwrite) as tmp:
            result = run(exp, args.fmu_dir, progress=args.progress)
            written = [out / p.relative_to(tmp) for p in write_outputs(result, tmp)]
    else:
        result = run(exp, args.fmu_dir, progress=args.progress)
    if args.json:
        from .results_io import to_jsonable
        print(json.dumps(to_jsonable(tagged_summary(result.summary)), indent=2,
                         allow_nan=False))
    else:
        print("\n".join(describe(result.summary)))
        for path in written:
            print(f"wrote {path}")
    return 0


def cmd_table41(args: argparse.Namespace) -> int:
    from .table41 import REPORT_TABLE, table41

    check_table41(args)
    check_fmu_dir("--fmu-dir", args.fmu_dir, FMU_NAMES)
    try:
        # closed form first (cheap): its speeds must be ones an ABU reaches before co-simulating
        check_table41_speeds(table41(args.mu, theta_ref_mode=args.theta_ref, t_step=args.t_step,
                                     step_hz=args.step_hz, check=False))
        started = time.perf_counter()
        rows = table41(args.mu, theta_ref_mode=args.theta_ref, t_step=args.t_step,
                       step_hz=args.step_hz, check=not args.no_check, fmu_dir=args.fmu_dir)
    except ParameterError as exc:
        raise _renamed(exc) from None
    if args.json:
        from .results_io import to_jsonable
        print(json.dumps(to_jsonable([r.as_dict() for r in rows]), indent=2, allow_nan=False))
        print(f"wall time {time.perf_counter() - started:.2f} s", file=sys.stderr)
        return 0
    print(f"{'mu [-]':>12} {'omega0 [Hz]':>12} {'threshold [Hz]':>15} {'jump [rad/s^2]':>15} "
          f"{'report [Hz]':>12} {'checked':>8}")
    for r in rows:
        report = next((f for mu, f in REPORT_TABLE.items() if abs(mu - r.mu) <= 1e-12), None)
        checked = {None: "-", True: "yes", False: "NO"}[r.consistent]
        print(f"{r.mu:>12.4g} {r.omega0_hz:>12d} {r.threshold_hz:>15.4f} {r.jump_rad_s2:>15.4f} "
              f"{'' if report is None else report:>12} {checked:>8}")
    print(f"wall time {time.perf_counter() - started:.2f} s")
    return 0


def cmd_sweep(args: argparse.Namespace) -> int:
    from fmus.build import build_fmus

    from .experiments import StaircaseExperiment
    from .sweep import run_sweep, sweep_grid, write_sweep_csv

    if args.workers < 1:
        raise ParameterError("--workers", args.workers, "at least 1 worker process")
    check_sweep(args)
    check_fmu_dir("--fmu-dir", args.fmu_dir, FMU_NAMES)
    span = _finite("--span-hz", args.span_hz)
    if abs(span) < 1.0:
        raise ParameterError("--span-hz", span, "a span of at least one 1 Hz step")
    out = Path(args.out)
    fmu_dir = Path(args.fmu_dir) if args.fmu_dir else out.parent / "fmus"
    points = sweep_grid(args.mu, args.omega0_hz)
    w0 = points[0].omega0_hz * HZ
    try:
        base = StaircaseExperiment(PlantParams(), w0, w0 + span * HZ, te=args.te,
                                   rounding=args.rounding, theta_ref_mode=args.theta_ref,
                                   zeta=args.zeta, omega_n=args.omega_n)
    except ParameterError as exc:
        raise _renamed(exc) from None
    with output_file(out, overwrite=args.overwrite) as tmp:  # locked before the runs
        build_fmus(fmu_dir)
        started = time.perf_counter()
        rows = run_sweep(points, base, fmu_dir, scheduler=args.scheduler,
                         workers=args.workers, progress=args.progress)
        wall = time.perf_counter() - started
        write_sweep_csv(tmp, rows)
    bracketed = sum(r["bracketed"] for r in rows)
    slipped = sum(r["slipped"] for r in rows)
    print(f"{len(rows)} runs: {slipped} slipped, {bracketed} bracket mu; wrote {out} "
          f"(wall time {wall:.2f} s)")
    return 0


def _rename(args: argparse.Namespace, exc: ParameterError) -> ParameterError:
    """A library ParameterError named as the option the user typed."""
    return option_error(exc, OPTION_OF, getattr(args, "_parser", None))


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``abu`` command line; returns the exit status (2 for user errors, 1 for an
    unexpected error, reported in one line; ``--debug`` shows its traceback)."""
    return run_command(build_parser, argv, rename=_rename)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
