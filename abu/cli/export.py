"""``abu export-ssp``: the staircase experiment as an SSP 1.0 archive for other FMI tools.

Takes the same staircase, speed-controller and plant options as ``abu simulate`` (defined in
:mod:`abu.cli.options_cosim`) plus ``--comm-step`` and ``--native`` (the native C FMUs, which
need no Python, instead of the pythonfmu ones), builds the three FMUs fresh and writes
``SystemStructure.ssd``, the FMUs and the parameter set into one ``.ssp`` file
(:mod:`fmus.ssp`). The archive runs unchanged in libcosimpy (``from_ssp_file``) and
``fmpy.ssp.simulate_ssp``; see docs/fmus.md.
"""
from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

from abu_model.errors import ParameterError

from abu.cli.common import MAX_COMM_STEPS, add_overwrite, count_limit
from abu.cli.options_cosim import (add_controller_options, add_plant_options,
                                   add_staircase_options, staircase_defaults,
                                   staircase_from_args)
from abu.cli.output_tx import output_file

SSP_SUFFIX = ".ssp"


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``export-ssp`` to the ``abu`` subcommands."""
    p = subparsers.add_parser(
        "export-ssp", help="write the staircase experiment as an SSP 1.0 archive (FMUs, "
                           "connections, parameters) for libcosim, fmpy and other tools",
        description="Build the FMUs and write the closed-loop staircase experiment (Staircase -> "
                    "SpeedController <-> AbuBall) as an SSP 1.0 archive: the FMUs, "
                    "SystemStructure.ssd (typed connectors with units, connections, default "
                    "experiment with the fixed communication step) and the parameter set "
                    "resources/abu.ssv for the options given. A fixed-step (Jacobi) master "
                    "lands no communication point on setpoint steps or stick/slip switches: "
                    "use 'abu simulate' for the exact bounds.")
    p.add_argument("--out", required=True, help="the .ssp file to write")
    add_staircase_options(p)
    add_controller_options(p)
    add_plant_options(p)
    g = p.add_argument_group("run")
    g.add_argument("--comm-step", type=float, default=1e-3,
                   help="fixed communication step of the default experiment [s] (default 0.001)")
    g.add_argument("--native", action="store_true",
                   help="package the native C FMUs (no Python needed; linux64, win64 if the "
                        "mingw-w64 cross compiler is installed, and sources/) instead of the "
                        "pythonfmu ones")
    add_overwrite(g)
    # a fixed-step archive: no error-controlled steps (simulate's --tol) to describe
    p.set_defaults(func=cmd_export_ssp, tol=None)


def cmd_export_ssp(args: argparse.Namespace) -> int:
    """Validate the options, build the FMUs into a temporary folder, write the archive."""
    from fmus.build import build_fmus
    from fmus.native_build import build_native_fmus
    from fmus.ssp import Experiment, write_ssp

    out = Path(args.out)
    if out.suffix.lower() != SSP_SUFFIX:
        raise ParameterError("--out", args.out, "a file name ending in .ssp")
    # the staircase, controller and plant options at their defaults under ours
    merged = staircase_defaults()
    vars(merged).update(vars(args))
    exp = staircase_from_args(merged)  # every option checked, errors name the option
    experiment = Experiment(exp.t_start, exp.t_end, exp.comm_step)
    count_limit("--comm-step", exp.comm_step, (exp.t_end - exp.t_start) / exp.comm_step,
                MAX_COMM_STEPS, "communication steps", "a host would take hours; a typo")
    # the target is checked (and locked) first: a refused --out costs no FMU build
    with output_file(out, overwrite=args.overwrite) as target, \
            tempfile.TemporaryDirectory(prefix="abu_ssp_fmus_") as tmp:
        system = exp.system(build_native_fmus(tmp) if args.native else build_fmus(tmp))
        write_ssp(target, system.components, system.connections, experiment)
    print(f"wrote {out} (start {exp.t_start:g} s, stop {exp.t_end:g} s, "
          f"step {exp.comm_step:g} s; components ref, ctrl, plant"
          f"{', native FMUs' if args.native else ''})")
    return 0

