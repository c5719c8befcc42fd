"""The ``abu`` command line: one parser, one module per group of commands.

* :mod:`abu.cli.simulate`: ``build-fmus``, ``simulate``, ``table41``;
* :mod:`abu.cli.sweep`: ``sweep``;
* :mod:`abu.cli.export`: ``export-ssp``;
* :mod:`abu.cli.measure`: ``track``, ``measure``, ``measure-summary``;
* :mod:`abu.cli.render`: ``render``; :mod:`abu.cli.camera`: ``calibrate-camera``;
* :mod:`abu.cli.plan`: ``identify``, ``design``, ``next``;
* :mod:`abu.cli.demo`: ``demo``.

Each command parses, checks, calls the library and writes. Speeds are given in Hz on the
command line (options ending ``-hz``) and converted to rad/s at once; everything else is SI.
A user error (:class:`abu_model.errors.AbuError`) prints one line naming the option on stderr
and exits with status 2, without a traceback. Nothing below this package imports it.
"""
from __future__ import annotations

import argparse
import sys
from typing import Sequence

from abu_model.errors import ParameterError

from abu.cli.common import AbuArgumentParser, option_error, run_command
from abu.cli.measure import OPTION_OF as MEASURE_OPTION_OF
from abu.cli.not_applicable import check_not_applicable
from abu.cli.options_cosim import OPTION_OF as COSIM_OPTION_OF

#: Library parameter name -> command-line option (for error messages).
OPTION_OF = {**MEASURE_OPTION_OF, **COSIM_OPTION_OF}


class _VersionAction(argparse.Action):
    """``--version``: the installed version, looked up only when asked (see abu.__getattr__)."""

    def __init__(self, option_strings, dest, **kwargs):
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS,
                         help="show the program's version number and exit")

    def __call__(self, parser, namespace, values, option_string=None):
        import abu

        parser.exit(message=f"{parser.prog} {abu.__version__}\n")


def build_parser() -> argparse.ArgumentParser:
    """The ``abu`` argument parser with every subcommand."""
    from abu.cli import camera, demo, export, measure, plan, render, simulate, sweep

    parser = AbuArgumentParser(
        prog="abu", description="Static friction of a ball in an automatic balancing unit: "
                                "FMI co-simulation and high-speed camera measurement.")
    parser.add_argument("--version", action=_VersionAction)
    parser.add_argument("--debug", action="store_true",
                        help="show the traceback of an unexpected error (any position)")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for module in (simulate, sweep, demo, measure, render, camera, export, plan):
        module.register(sub)
    return parser


def _rename(args: argparse.Namespace, exc: ParameterError) -> ParameterError:
    """A library ParameterError named as the option the user typed."""
    return option_error(exc, OPTION_OF, getattr(args, "_parser", None))


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``abu`` command line; returns the exit status (2 for user errors, 1 for an
    unexpected error, reported in one line; ``--debug`` shows its traceback)."""
    return run_command(build_parser, argv, rename=_rename, precheck=check_not_applicable)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
