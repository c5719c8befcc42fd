"""Co-simulation commands: ``build-fmus``, ``simulate`` (its files and text:
:mod:`harness.experiments.simulate_output`) and ``table41`` (``sweep``: :mod:`abu.cli.sweep`)."""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from abu_model.errors import ParameterError

from abu.cli.checks_cosim import (check_fmu_dir, check_ramp, check_staircase,
                                  check_table41, check_table41_speeds)
from abu.cli.common import add_figure_format, add_overwrite
from abu.cli.options_cosim import (add_controller_options, add_plant_options,
                                   add_staircase_options, ramp_from_args, renamed,
                                   staircase_from_args)
from abu.cli.output_tx import output_folder
from harness.experiments.simulate_output import describe, tagged_summary, write_outputs

FMU_NAMES = ("AbuBall", "SpeedController", "Staircase")
#: ``abu table41 --json``: an object with its kind, format version, units and one row per mu.
TABLE41_KIND = "abu-table41"
TABLE41_UNITS = {"mu": "-", "omega0_hz": "Hz", "threshold_hz": "Hz", "jump_rad_s2": "rad/s^2",
                 "check.omega0_hz": "Hz"}


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``build-fmus``, ``simulate`` and ``table41`` to the subcommands."""
    p = sub.add_parser("build-fmus", help="build AbuBall.fmu, SpeedController.fmu, Staircase.fmu",
                       description="Build the three FMI 2.0 co-simulation FMUs: pythonfmu "
                                   "(default) or, with --native, compiled C that needs no "
                                   "Python (linux64, win64 if the mingw-w64 cross compiler "
                                   "is installed, and sources/).")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--native", action="store_true",
                   help="build the native C FMUs (a C compiler needed; see docs/fmus.md)")
    add_overwrite(p)
    p.set_defaults(func=cmd_build_fmus)

    p = sub.add_parser("simulate", help="co-simulate the staircase or the ramp experiment",
                       description="Co-simulate an experiment of the report (ch. 4) on the FMUs "
                                   "and compute the friction bounds mu_low <= mu < mu_high.")
    p.add_argument("--motion", choices=["staircase", "ramp", "profile"], default="staircase",
                   help="staircase of setpoints (sec. 4.2, default), prescribed acceleration "
                        "ramp (sec. 4.1) or a tracking drive following --profile (ch. 6)")
    add_staircase_options(p)
    add_controller_options(p)
    g = p.add_argument_group("ramp")
    g.add_argument("--jerk", type=float, default=3000.0,
                   help="growth rate K of |omega_dot| [rad/s^3] (default 3000)")
    add_plant_options(p)
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
    g.add_argument("--out", default=None, help="write result.csv, summary.json and the figures "
                                               "here")
    add_overwrite(g)
    add_figure_format(g)
    g.add_argument("--json", action="store_true", help="print the summary as JSON on stdout")
    g.add_argument("--progress", action="store_true", help="show a progress bar on stderr")
    p.add_argument("--drive", default=None, help="drive.json of 'abu identify': its zeta, "
                   "omega_n and tau_motor replace --zeta, --omega-n, --tau-motor; with "
                   "--motion profile a drive of model tracking")
    p.add_argument("--profile", default=None, help="--motion profile: the profile.json ('abu "
                   "design' with a tracking drive) the --drive follows")
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



def cmd_build_fmus(args: argparse.Namespace) -> int:
    from fmus.build import build_fmus
    from fmus.native_build import build_native_fmus, platforms

    out = Path(args.out)
    with output_folder(out, overwrite=args.overwrite) as tmp:
        built = build_native_fmus(tmp) if args.native else build_fmus(tmp)
        carries = {name: platforms(path) for name, path in built.items()} if args.native else {}
    for name, path in built.items():
        extra = f" ({', '.join(carries[name])})" if args.native else ""
        print(f"{name}: {out / path.name}{extra}")
    return 0


def cmd_simulate(args: argparse.Namespace) -> int:
    from harness.experiments.staircase import run_ramp, run_staircase

    if args.motion == "profile":
        from abu.cli.options_profile import profile_experiment_from_args
        from harness.experiments.profile_run import run_profile
        exp = profile_experiment_from_args(args)
        check_fmu_dir("--fmu-dir", args.fmu_dir, FMU_NAMES)
        run = run_profile
    else:
        from abu.cli.plan import apply_drive_to_args
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
            written = [out / p.relative_to(tmp)
                       for p in write_outputs(result, tmp, args.figure_format)]
    else:
        result = run(exp, args.fmu_dir, progress=args.progress)
    if args.json:
        from harness.experiments.results_io import to_jsonable
        print(json.dumps(to_jsonable(tagged_summary(result.summary)), indent=2,
                         allow_nan=False))
    else:
        print("\n".join(describe(result.summary)))
        for path in written:
            print(f"wrote {path}")
    return 0


def cmd_table41(args: argparse.Namespace) -> int:
    from harness.experiments.table41 import REPORT_TABLE, table41

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
        raise renamed(exc) from None
    if args.json:
        from harness.experiments.results_io import to_jsonable
        table = {"kind": TABLE41_KIND, "format_version": 1, "units": TABLE41_UNITS,
                 "rows": [r.as_dict() for r in rows]}
        print(json.dumps(to_jsonable(table), indent=2, allow_nan=False))
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
