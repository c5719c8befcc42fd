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


#: Command -> the module of :mod:`abu.cli` that registers it. A command line naming one of
#: them builds only that module's parsers: the others import the twin, the harness or the
#: camera calibration (~40 ms of the ~0.7 s budget of ``abu measure``; tests/test_measure_cli.py
#: checks that this map matches the full parser).
COMMAND_MODULE = {"build-fmus": "simulate", "simulate": "simulate", "table41": "simulate",
                  "sweep": "sweep", "demo": "demo", "track": "measure", "measure": "measure",
                  "measure-summary": "measure", "render": "render",
                  "calibrate-camera": "camera", "export-ssp": "export", "identify": "plan",
                  "design": "plan", "next": "plan"}
_MODULES = ("simulate", "sweep", "demo", "measure", "render", "camera", "export", "plan")


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The ``abu`` argument parser with every subcommand, or with only the commands of the
    module that registers ``command`` (when it is one of :data:`COMMAND_MODULE`)."""
    import importlib

    parser = AbuArgumentParser(
        prog="abu", description="Static friction of a ball in an automatic balancing unit: "
                                "FMI co-simulation and high-speed camera measurement.")
    parser.add_argument("--version", action=_VersionAction)
    parser.add_argument("--debug", action="store_true",
                        help="show the traceback of an unexpected error (any position)")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    names = (COMMAND_MODULE[command],) if command in COMMAND_MODULE else _MODULES
    for name in names:
        importlib.import_module(f"abu.cli.{name}").register(sub)
    return parser


def _command_of(argv: Sequence[str] | None) -> str | None:
    """The command a command line names: its first word that is not an option (the global
    options, ``--version`` and ``--debug``, take no value); None after a global ``-h`` (the
    top-level help lists every command)."""
    for word in sys.argv[1:] if argv is None else argv:
        if word in ("-h", "--help"):
            return None
        if not word.startswith("-"):
            return word
    return None


def _rename(args: argparse.Namespace, exc: ParameterError) -> ParameterError:
    """A library ParameterError named as the option the user typed."""
    return option_error(exc, OPTION_OF, getattr(args, "_parser", None))


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``abu`` command line; returns the exit status (2 for user errors, 1 for an
    unexpected error, reported in one line; ``--debug`` shows its traceback)."""
    command = _command_of(argv)
    return run_command(lambda: build_parser(command), argv, rename=_rename,
                       precheck=check_not_applicable)


def console_main() -> None:
    """The ``abu`` program (``[project.scripts]``): :func:`main` on ``sys.argv``, then the
    process ends without freeing its modules one by one (:mod:`abu.cli.process_exit`); its
    figures are drawn without matplotlib's generated docstrings (:mod:`abu.cli.figure_startup`)."""
    from abu.cli.figure_startup import install
    from abu.cli.process_exit import exit_process

    install()
    exit_process(main())


if __name__ == "__main__":  # pragma: no cover
    console_main()
