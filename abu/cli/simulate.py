"""Co-simulation commands: ``build-fmus``, ``simulate`` (its files and text:
:mod:`harness.experiments.simulate_output`), ``table41`` and ``sweep``."""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from abu_model.errors import ParameterError
from abu_model.params import PlantParams

from abu.cli.checks_cosim import (check_fmu_dir, check_ramp, check_staircase, check_sweep,
                                  check_table41, check_table41_speeds)
from abu.cli.common import add_figure_format, add_overwrite
from abu.cli.options_cosim import (HZ, add_controller_options, add_plant_options,
                                   add_staircase_options, finite, ramp_from_args, renamed,
                                   staircase_from_args)
from abu.cli.output_tx import output_file, output_folder
from harness.experiments.simulate_output import describe, tagged_summary, write_outputs

FMU_NAMES = ("AbuBall", "SpeedController", "Staircase")
#: ``abu table41 --json``: an object with its kind, format version, units and one row per mu.
TABLE41_KIND = "abu-table41"
TABLE41_UNITS = {"mu": "-", "omega0_hz": "Hz", "threshold_hz": "Hz", "jump_rad_s2": "rad/s^2",
                 "check.omega0_hz": "Hz"}


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``build-fmus``, ``simulate``, ``table41`` and ``sweep`` to the subcommands."""
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
    add_controller_options(p)
    p.add_argument("--workers", type=int, default=2, help="local worker processes (default 2)")
    p.add_argument("--scheduler", default=None,
                   help="address of a running Dask scheduler (default: start a local cluster)")
    p.add_argument("--fmu-dir", default=None, help="folder with the FMUs, readable by every worker "
                                                   "(default: built into --out's folder)")
    p.add_argument("--out", required=True, help="CSV file to write")
    add_overwrite(p)
    p.add_argument("--progress", action="store_true", help="show a progress bar on stderr")
    p.set_defaults(func=cmd_sweep)



def cmd_build_fmus(args: argparse.Namespace) -> int:
    from fmus.build import build_fmus

    out = Path(args.out)
    with output_folder(out, overwrite=args.overwrite) as tmp:
        built = build_fmus(tmp)
    for name, path in built.items():
        print(f"{name}: {out / path.name}")
    return 0


def cmd_simulate(args: argparse.Namespace) -> int:
    from harness.experiments.staircase import run_ramp, run_staircase

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


def cmd_sweep(args: argparse.Namespace) -> int:
    from fmus.build import build_fmus

    from harness.experiments.staircase import StaircaseExperiment
    from harness.experiments.sweep import run_sweep, sweep_grid, write_sweep_csv

    if args.workers < 1:
        raise ParameterError("--workers", args.workers, "at least 1 worker process")
    check_sweep(args)
    check_fmu_dir("--fmu-dir", args.fmu_dir, FMU_NAMES)
    span = finite("--span-hz", args.span_hz)
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
        raise renamed(exc) from None
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
