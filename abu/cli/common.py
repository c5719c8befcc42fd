"""Shared command-line infrastructure of ``abu``: parser, option checks, error reporting.

* :class:`AbuArgumentParser`: negative numbers (``-1e6``, ``-inf``, ``-.5``) work as option
  values in both spellings (``--omega0-hz -1e6`` and ``--omega0-hz=-1e6``); a parse error is one
  line on stderr and exit status 2 (no usage block).
* Validators (:func:`finite`, :func:`positive`, :func:`in_range`, :func:`count_limit`) raise
  :class:`~abu_model.errors.ParameterError` naming the option as typed, the value, the limit and
  why. Limits on what a run implies (communication steps, frames, bins, samples) are here, one
  place, with the reason.
* :func:`option_error`: a library's ParameterError (``sg_window_s``, ``omega_end``...) renamed to
  the command-line option the user typed.
* :func:`run_command`: the top level: AbuError -> one line, exit 2; any other exception -> one
  line naming the command and its input, exit 1 (``--debug`` shows the traceback).
"""
from __future__ import annotations

import argparse
import math
import os
import re
import sys
import traceback
from typing import Callable, Iterable, Mapping, NoReturn, Sequence

from abu_model.errors import AbuError, ParameterError

#: A float literal with a leading minus, including -inf / -nan / -1e6 / -.5.
_NEGATIVE_NUMBER = re.compile(
    r"^-(\d+\.?\d*([eE][-+]?\d+)?|\.\d+([eE][-+]?\d+)?|inf|infinity|nan)$", re.IGNORECASE)

# ---------------------------------------------------------------------------- limits (why)
#: Communication steps of one co-simulation: about 0.4 ms each (benchmarks/bench_cosim.py), so
#: 2e6 steps take about 15 minutes; more is a typo (e.g. --comm-step 1e-9), not an experiment.
MAX_COMM_STEPS = 2_000_000
#: Setpoint steps of a staircase: each forces a communication point and a rollback check.
MAX_SETPOINT_STEPS = 100_000
#: Simulated time [s]: the report's experiments last about 1 s.
MAX_SIM_TIME_S = 1.0e4
#: Frames of a rendered or read recording (the report's camera holds 3072 frames per run).
MAX_FRAMES = 200_000
#: Pixels (frames x height x width) held in memory: 4 GiB of 8-bit frames.
MAX_PIXELS = 4 * 2**30
#: Histogram grid points (the histogram is only drawn from them; counts are exact).
MAX_BINS = 1_000_000
#: Samples of a tracks file / kinematics table.
MAX_SAMPLES = 10_000_000


class AbuArgumentParser(argparse.ArgumentParser):
    """ArgumentParser that accepts negative numbers as option values and errors in one line."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = _NEGATIVE_NUMBER

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")


# ---------------------------------------------------------------------------- validators
def finite(option: str, value: float, unit: str = "") -> float:
    """``value`` if finite, else ParameterError naming ``option``."""
    if value is None or not math.isfinite(value):
        raise ParameterError(option, value, f"a finite number{_u(unit)}")
    return float(value)


def positive(option: str, value: float | None, unit: str = "", *,
             allow_none: bool = False, allow_zero: bool = False) -> float | None:
    """``value`` if finite and > 0 (>= 0 with ``allow_zero``)."""
    if value is None and allow_none:
        return None
    if value is None or not math.isfinite(value) or value < 0 or (value == 0 and not allow_zero):
        raise ParameterError(option, value,
                             f"a finite number {'>=' if allow_zero else '>'} 0{_u(unit)}")
    return float(value)


def camera_fps(option: str, value: float) -> float:
    """A camera's frame rate [frames/s] in [1, MAX_CAMERA_FPS_HZ] (one limit for every command)."""
    from abu_model.params import MAX_CAMERA_FPS_HZ
    return in_range(option, value, 1.0, MAX_CAMERA_FPS_HZ, "frames/s",
                    "a camera's frame rate; burst cameras record up to 1e7 frames/s")


def in_range(option: str, value: float, low: float, high: float, unit: str = "",
             why: str = "") -> float:
    """``value`` if finite and low <= value <= high."""
    if value is None or not math.isfinite(value) or not low <= value <= high:
        reason = f" ({why})" if why else ""
        raise ParameterError(option, value, f"a number in [{low:g}, {high:g}]{_u(unit)}{reason}")
    return float(value)


def count_limit(option: str, value: object, count: float, limit: float, what: str,
                why: str) -> None:
    """Refuse an option whose value implies ``count`` > ``limit`` of ``what`` (steps, frames...).

    The message names the option, its value, the count it implies, the limit and why.
    """
    if not (count <= limit):  # also catches NaN
        raise ParameterError(option, value, f"at most {limit:.3g} {what} ({why}); this value "
                             f"implies {count:.3g}")


def integer_range(option: str, value: int, low: int, high: int, why: str = "") -> int:
    """``value`` if low <= value <= high (integers)."""
    if not low <= value <= high:
        reason = f" ({why})" if why else ""
        raise ParameterError(option, value, f"an integer in [{low}, {high}]{reason}")
    return int(value)


def _u(unit: str) -> str:
    return f" {unit}" if unit else ""


# ---------------------------------------------------------------------------- error naming
def add_figure_format(p) -> None:
    """``--figure-format png|pdf|svg`` (every command that draws figures)."""
    from abu_model.figure_files import FIGURE_FORMATS, PNG_DPI
    p.add_argument("--figure-format", choices=FIGURE_FORMATS, default="png",
                   help=f"file format of the figures: png ({PNG_DPI} dpi, default), or pdf / "
                        "svg (vector, for print)")


def log(args: argparse.Namespace, message: str) -> None:
    """A progress message on stderr, unless the command runs with ``--quiet``."""
    if not getattr(args, "quiet", False):
        print(message, file=sys.stderr)


def option_names(parser: argparse.ArgumentParser) -> set[str]:
    """Every option string (``--out``...) of ``parser``."""
    return {s for action in parser._actions for s in action.option_strings}


def option_error(exc: ParameterError, mapping: Mapping[str, str] | None = None,
                 parser: argparse.ArgumentParser | None = None) -> ParameterError:
    """``exc`` renamed to the command-line option: by ``mapping`` (library name -> option), else
    ``--`` + the name with ``-`` for ``_`` when ``parser`` has that option; unchanged otherwise."""
    name = exc.parameter
    if name.startswith("-"):
        return exc
    option = (mapping or {}).get(name)
    if option is None and parser is not None:
        guess = "--" + name.replace("_", "-")
        if guess in option_names(parser):
            option = guess
    if option is None:
        return exc
    renamed = ParameterError(option, exc.value, exc.expected)
    return renamed


# ---------------------------------------------------------------------------- top level
def _strip_debug(argv: Sequence[str]) -> tuple[list[str], bool]:
    args = list(argv)
    if "--debug" in args:
        end = args.index("--") if "--" in args else len(args)
        if "--debug" in args[:end]:
            args = [a for i, a in enumerate(args) if not (a == "--debug" and i < end)]
            return args, True
    return args, False


def _input_of(args: argparse.Namespace) -> str:
    for name in ("input", "summaries", "out", "fmu_dir"):
        value = getattr(args, name, None)
        if value:
            if isinstance(value, (list, tuple)):
                value = " ".join(str(v) for v in value)
            return f"{name} '{value}'"
    return "its options"


def run_command(build_parser: Callable[[], argparse.ArgumentParser],
                argv: Sequence[str] | None, *,
                rename: Callable[[argparse.Namespace, ParameterError], ParameterError]
                | None = None,
                precheck: Callable[[str, argparse.Namespace], None] | None = None) -> int:
    """Parse ``argv`` and run ``args.func(args)`` with the toolkit's error policy.

    * AbuError (bad option or input, locked or existing output): ``abu CMD: error: ...`` on one
      line, exit 2.
    * OSError on a path (unreadable input, unwritable output): one line, exit 2.
    * anything else: ``abu CMD: internal error on INPUT: Type: message`` on one line, exit 1;
      with ``--debug`` (anywhere before ``--``) the traceback is printed too.
    * KeyboardInterrupt: exit 130; stdout closed by its reader (``| head``): exit 141, quiet.

    ``precheck(command, args)`` runs first (the options a mode ignores are refused there).
    """
    from abu.cli.output_tx import use_run_tempdir

    argv, debug = _strip_debug(sys.argv[1:] if argv is None else argv)
    parser = build_parser()
    track_given(parser)
    args = parser.parse_args(argv)
    command = getattr(args, "command", None) or parser.prog
    args._parser = _subparser(parser, command)
    use_run_tempdir()
    try:
        check_float_options(args._parser, args)
        if precheck is not None:
            precheck(command, args)
        status = int(args.func(args) or 0)
        sys.stdout.flush()  # a closed pipe shows here, inside the error policy, not at exit
        return status
    except ParameterError as exc:
        if rename is not None:
            exc = rename(args, exc)
        _error_line(command, str(exc), debug)
        return 2
    except AbuError as exc:
        _error_line(command, str(exc), debug)
        return 2
    except BrokenPipeError:
        # the reader of stdout went away (``abu ... | head``): the results are written;
        # stop quietly with the shell's status for SIGPIPE, as other Unix tools do
        _silence_stdout()
        return 141
    except OSError as exc:
        if exc.filename is None:  # not about a path the user gave: unexpected
            return _internal(command, args, exc, debug)
        _error_line(command, _os_message(exc), debug)
        return 2
    except KeyboardInterrupt:
        print(f"abu {command}: interrupted", file=sys.stderr)
        return 130
    except SystemExit:
        raise
    except BaseException as exc:  # noqa: BLE001 - the last line of defence: no traceback
        return _internal(command, args, exc, debug)


def check_float_options(parser: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """Every ``type=float`` option holds finite numbers (no option here means anything by inf or
    NaN, and they would otherwise travel into a computation)."""
    for action in parser._actions:
        if action.type is None and not action.choices and action.nargs != 0 and \
                action.dest not in ("help", "command", "func"):
            value = getattr(args, action.dest, None)
            for v in value if isinstance(value, list) else [value]:
                if isinstance(v, str) and not v.strip():
                    name = action.option_strings[0] if action.option_strings else \
                        (action.metavar or action.dest.upper())
                    raise ParameterError(name, v, "a non-empty value (an empty path would mean "
                                         "the current folder or nothing)")
        if action.type is not float or not action.option_strings:
            continue
        value = getattr(args, action.dest, None)
        for v in value if isinstance(value, list) else [value]:
            if v is not None and not math.isfinite(v):
                raise ParameterError(action.option_strings[0], v, "a finite number")


def _subparser(parser: argparse.ArgumentParser, command: str) -> argparse.ArgumentParser:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction) and command in action.choices:
            return action.choices[command]
    return parser


def _silence_stdout() -> None:
    """Point stdout at /dev/null so that the interpreter's final flush of the closed pipe
    does not print 'Exception ignored ... BrokenPipeError'."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):  # no real file descriptor (in-process use)
        pass


def _os_message(exc: OSError) -> str:
    where = f"'{exc.filename}'" + (f" -> '{exc.filename2}'" if exc.filename2 else "")
    return f"{where}: {exc.strerror or exc}"


def _error_line(command: str, message: str, debug: bool) -> None:
    if debug:
        traceback.print_exc()
    print(f"abu {command}: error: {' '.join(message.split())}", file=sys.stderr)


def _internal(command: str, args: argparse.Namespace, exc: BaseException, debug: bool) -> int:
    if debug:
        traceback.print_exc()
    text = " ".join(str(exc).split())[:300]
    hint = "" if debug else "; run again with --debug for the traceback"
    print(f"abu {command}: internal error on {_input_of(args)}: {type(exc).__name__}: {text}"
          f"{hint}", file=sys.stderr)
    return 1


# ---------------------------------------------------------------------------- given options
#: Namespace attribute holding the dests of the options the user typed (see track_given).
_GIVEN = "_given_options"
_RECORDING_CLASSES: dict[type, type] = {}


def _recording_class(cls: type) -> type:
    """A subclass of the argparse action ``cls`` that notes its dest when argparse calls it
    (it calls an optional's action only when the option is on the command line, whatever the
    spelling: ``--opt v``, ``--opt=v``, an abbreviation ``--op v``)."""
    if cls not in _RECORDING_CLASSES:
        def __call__(self, parser, namespace, values, option_string=None):
            if option_string is not None:
                given = getattr(namespace, _GIVEN, None)
                if given is None:
                    given = set()
                    setattr(namespace, _GIVEN, given)
                given.add(self.dest)
            return cls.__call__(self, parser, namespace, values, option_string)

        _RECORDING_CLASSES[cls] = type("Given" + cls.__name__, (cls,), {"__call__": __call__})
    return _RECORDING_CLASSES[cls]


def track_given(parser: argparse.ArgumentParser) -> None:
    """Make ``parser`` (and its subparsers) note which options the user gave explicitly, so
    that a command can refuse an option its mode ignores (:func:`refuse_given`)."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                track_given(sub)
        elif action.option_strings and not isinstance(action, (argparse._HelpAction,
                                                               argparse._VersionAction)):
            if not type(action).__name__.startswith("Given"):
                action.__class__ = _recording_class(type(action))


def given(args: argparse.Namespace, option: str) -> bool:
    """True if ``option`` (``--mu``) was on the command line (see :func:`track_given`)."""
    return option.lstrip("-").replace("-", "_") in getattr(args, _GIVEN, set())


def refuse_given(args: argparse.Namespace, options: Iterable[str], why: str) -> None:
    """Refuse the first of ``options`` the user gave explicitly: the chosen mode ignores it.

    ``why`` completes "expected no OPTION ...", e.g. ``"with --scenario random (its mu is drawn
    from --seed)"``.
    """
    for option in options:
        if given(args, option):
            value = getattr(args, option.lstrip("-").replace("-", "_"), None)
            raise ParameterError(option, value, f"no {option} {why}")


def add_overwrite(p: argparse.ArgumentParser) -> None:
    """The ``--overwrite`` flag of every command that writes an output."""
    p.add_argument("--overwrite", action="store_true",
                   help="replace the results of a previous run in --out")


def names_in(options: Iterable[str]) -> str:
    """``--a, --b`` for messages."""
    return ", ".join(options)
