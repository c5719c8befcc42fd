"""``abu sweep``: many ``abu simulate --motion staircase`` runs over a grid, on Dask.

Every option of ``abu simulate --motion staircase`` applies to each run (plant, controller,
staircase, ``--drive``, ``--comm-step``, ``--tol``, ``--fmu-dir``...); the grid options
replace their single-valued namesakes: ``--mu`` and ``--omega0-hz`` take lists, and each
staircase spans ``--span-hz`` from its omega0 (or ends at ``--omega-end-hz``). Each finished
run is appended to ``<out>.journal`` as it lands; the same command started again resumes from
it (library: :mod:`harness.experiments.sweep`, :mod:`harness.experiments.sweep_journal`).
"""
from __future__ import annotations

import argparse
import copy
import json
import time
from pathlib import Path

from abu_model.errors import ParameterError

from abu.cli.checks_cosim import check_fmu_dir, check_scheduler_address, check_staircase
from abu.cli.common import add_overwrite, count_limit
from abu.cli.options_cosim import (add_controller_options, add_plant_options,
                                   add_staircase_options, staircase_from_args)

FMU_NAMES = ("AbuBall", "SpeedController", "Staircase")
#: Largest grid accepted (runs).
MAX_RUNS = 1_000_000
#: The report's span omega_end - omega0 [Hz], the default of --span-hz.
DEFAULT_SPAN_HZ = -5.0
SWEEP_KIND = "abu-sweep"


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``sweep`` to the subcommands."""
    p = sub.add_parser(
        "sweep", conflict_handler="resolve",
        help="staircase co-simulations over a grid of mu and omega0 on a Dask cluster",
        description="Run 'abu simulate --motion staircase' for every (mu, omega0) pair, one "
                    "co-simulation per worker process (local cluster, or a running Dask "
                    "scheduler), and write the bounds as CSV. Every simulate option applies "
                    "to each run. Finished runs are journalled in OUT.journal as they land: "
                    "the same command started again resumes where it stopped.")
    p.add_argument("--motion", choices=["staircase"], default="staircase",
                   help="the experiment (staircase only, as in abu simulate)")
    add_staircase_options(p)
    add_controller_options(p)
    add_plant_options(p)
    # the grid: these replace the single-valued options of the same names
    g = p.add_argument_group("grid")
    g.add_argument("--mu", type=float, nargs="+", required=True,
                   help="static friction coefficients [-]")
    g.add_argument("--omega0-hz", type=float, nargs="+", required=True,
                   help="initial speeds [Hz]; each staircase spans --span-hz from its omega0")
    g.add_argument("--span-hz", type=float, default=None,
                   help=f"omega_end - omega0 [Hz] (default {DEFAULT_SPAN_HZ:g}, the report's)")
    g.add_argument("--omega-end-hz", type=float, default=None,
                   help="a common end speed of every staircase [Hz] (instead of --span-hz)")
    g = p.add_argument_group("run")
    g.add_argument("--comm-step", type=float, default=None,
                   help="fixed communication step [s] (as in abu simulate)")
    g.add_argument("--tol", type=float, default=None,
                   help="coupling error tolerance [-] of the error-controlled steps (as in "
                        "abu simulate; default 1e-9)")
    g.add_argument("--drive", default=None, help="drive.json of 'abu identify': its zeta, "
                   "omega_n and tau_motor replace --zeta, --omega-n, --tau-motor")
    g.add_argument("--workers", type=int, default=2, help="local worker processes (default 2)")
    g.add_argument("--scheduler", default=None,
                   help="address of a running Dask scheduler, e.g. tcp://host:8786 (default: "
                        "start a local cluster)")
    g.add_argument("--fmu-dir", default=None, help="folder with the FMUs, readable by every "
                   "worker (built there if missing; default: built into --out's folder)")
    g.add_argument("--out", required=True, help="CSV file to write (journal: OUT.journal)")
    add_overwrite(g)
    g.add_argument("--json", action="store_true", help="print the rows as JSON on stdout")
    g.add_argument("--progress", action="store_true",
                   help="show a progress bar of runs done / total on stderr")
    p.set_defaults(func=cmd_sweep)


def sweep_tasks(args: argparse.Namespace) -> list:
    """The runs the options describe, each checked as ``abu simulate`` checks its options."""
    from harness.experiments.sweep import SweepTask, sweep_grid

    if args.span_hz is not None and args.omega_end_hz is not None:
        raise ParameterError("--span-hz", args.span_hz, "either --span-hz or --omega-end-hz, "
                             "not both")
    try:
        points = sweep_grid(args.mu, args.omega0_hz)
    except ParameterError as exc:
        raise ParameterError(f"--{exc.parameter.replace('_', '-')}", exc.value,
                             exc.expected) from None
    count_limit("--mu", len(args.mu), len(points), MAX_RUNS, "runs (--mu x --omega0-hz)",
                "one co-simulation each")
    span = DEFAULT_SPAN_HZ if args.span_hz is None else args.span_hz
    tasks = []
    for point in points:
        run = copy.copy(args)
        run.mu, run.omega0_hz = point.mu, point.omega0_hz
        if args.omega_end_hz is None:
            run.omega_end_hz = point.omega0_hz + span
        if point.omega0_hz == 0:
            raise ParameterError("--omega0-hz", 0.0, "non-zero speeds [Hz] (no normal force at "
                                 "rest)")
        try:
            check_staircase(run)
            exp = staircase_from_args(run)
        except ParameterError as exc:
            if exc.parameter == "--omega-end-hz" and args.omega_end_hz is None:
                raise ParameterError("--span-hz", span, f"{exc.expected} (omega0 "
                                     f"{point.omega0_hz:g} Hz)") from None
            raise
        tasks.append(SweepTask(point, exp))
    return tasks


def cmd_sweep(args: argparse.Namespace) -> int:
    from abu.cli.output_tx import output_file
    from abu.cli.plan import apply_drive_to_args
    from harness.experiments.sweep import connect, run_tasks
    from harness.experiments.sweep_journal import (COLUMNS, Journal, journal_path,
                                                   journal_settings, settings_hash,
                                                   write_sweep_csv)

    if not 1 <= args.workers <= 256:
        raise ParameterError("--workers", args.workers, "1 to 256 local worker processes")
    apply_drive_to_args(args)
    check_fmu_dir("--fmu-dir", args.fmu_dir, FMU_NAMES)
    check_scheduler_address(args.scheduler)  # its syntax; whether it answers: connect()
    tasks = sweep_tasks(args)
    digest = settings_hash((t.key, t.experiment) for t in tasks)
    out = Path(args.out)
    client = cluster = None
    try:
        if args.scheduler is not None:  # fail fast, before anything is locked or built
            client, cluster = connect(args.scheduler)
        # a run of this very command killed after its CSV landed, before its journal went:
        # the CSV is this sweep's own, so finishing it again may replace it
        finishing = out.is_file() and journal_settings(journal_path(out.absolute())) == digest
        with output_file(out, overwrite=args.overwrite or finishing) as tmp:  # locked
            journal = Journal(journal_path(out.absolute()), digest, len(tasks),
                              discard=args.overwrite)
            try:
                fmu_dir = _fmus(args, out)
                if client is None:
                    client, cluster = connect(None, args.workers)
                started = time.perf_counter()
                resumed = len([t for t in tasks if t.key in journal.rows])
                rows = run_tasks(tasks, fmu_dir, client, journal=journal,
                                 progress=args.progress)
                wall = time.perf_counter() - started
                write_sweep_csv(tmp, rows)
            finally:
                journal.close()
    finally:
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()
    # last: the CSV is in place and the cluster closed (a kill while it closes leaves the
    # journal, so the same command finishes instead of refusing the CSV as another run's)
    journal.remove()
    if args.json:
        print(json.dumps({"kind": SWEEP_KIND, "format_version": 1, "columns": list(COLUMNS),
                          "rows": rows}, indent=2))
        return 0
    bracketed = sum(r["bracketed"] for r in rows)
    slipped = sum(r["slipped"] for r in rows)
    again = f", {resumed} from the journal" if resumed else ""
    print(f"{len(rows)} runs{again}: {slipped} slipped, {bracketed} bracket mu; wrote {out} "
          f"(wall time {wall:.2f} s)")
    return 0


def _fmus(args: argparse.Namespace, out: Path) -> Path:
    """The FMU folder: --fmu-dir (missing FMUs built there) or a fresh build beside --out."""
    if args.fmu_dir is not None:
        from harness.experiments.fmu_files import ensure_fmus
        ensure_fmus(args.fmu_dir)
        return Path(args.fmu_dir)
    from fmus.build import build_fmus
    fmu_dir = out.parent / "fmus"
    build_fmus(fmu_dir)
    return fmu_dir
