"""The one validation layer of every file the toolkit reads (standard library only).

Every reader (tracks CSV, summaries, intervals CSV, drive.json, camera.json, identify's record and
setpoint CSV, frame folders) checks the values it takes from a file through these functions, so
that one rule holds everywhere:

* **types**: a JSON ``true`` is not a number, a string is not a number (not even ``"0.02"``), a
  number is not a string; an integer field holds an integer;
* **finiteness** (no NaN, no infinity) and **ranges** (``lo`` / ``hi``, inclusive unless told);
* **uniqueness**: :func:`unique_names` (duplicate columns or keys), :func:`strictly_increasing`
  (duplicate or unordered times);
* **one line** naming the file, the field or row and what was expected:
  ``tracks.csv, data row 7, column 'x_cd': expected a finite number, got 'abc'``.

The functions raise :class:`InputError` (an :class:`~abu_model.errors.AbuError`: the command line
prints it in one line and exits with status 2); a reader may pass its own error class (a
subclass of AbuError whose constructor takes the message) with ``error=``.

This module imports nothing outside the standard library and this package's ``errors``: it runs
inside the FMUs (``controller.drive`` uses it).
"""
from __future__ import annotations

import math
from typing import Any, Callable, Iterable, Sequence

from .errors import AbuError


class InputError(AbuError, ValueError):
    """A value read from a file has the wrong type, is not finite, out of range or repeated."""


ErrorFactory = Callable[[str], Exception]


def where(source: object, *parts: object) -> str:
    """``source, part, part`` for messages (empty parts left out)."""
    return ", ".join(str(p) for p in (source, *parts) if p not in (None, ""))


def fail(place: str, expected: str, got: Any = None, *, show: bool = True,
         error: ErrorFactory = InputError) -> Exception:
    """The error ``place: expected EXPECTED, got GOT`` (returned, for ``raise``)."""
    text = f"{place}: expected {expected}"
    if show:
        text += f", got {_shown(got)}"
    return error(text)


def _shown(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"     # as JSON spells it
    if value is None:
        return "null"
    if isinstance(value, float):
        return repr(float(value))
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _range_text(lo: float | None, hi: float | None, lo_open: bool, hi_open: bool,
                unit: str) -> str:
    u = f" {unit}" if unit else ""
    if lo is not None and hi is not None:
        return (f" in {'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}{u}")
    if lo is not None:
        return f" {'>' if lo_open else '>='} {lo:g}{u}"
    if hi is not None:
        return f" {'<' if hi_open else '<='} {hi:g}{u}"
    return u


def is_number(value: Any) -> bool:
    """True for int and float values, False for bool (a JSON ``true`` is not a number)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def number(value: Any, place: str, *, lo: float | None = None, hi: float | None = None,
           lo_open: bool = False, hi_open: bool = False, integer: bool = False,
           finite: bool = True, unit: str = "", why: str = "",
           error: ErrorFactory = InputError) -> float:
    """``value`` as a float if it is a number (int or float, not bool, not a string) within range.

    Args:
        value: a value decoded from a file (JSON number, or a float parsed by :func:`cell`).
        place: where it comes from (``file, field 'mu_low'``), for the message.
        lo, hi: inclusive bounds (``lo_open`` / ``hi_open``: exclusive); None: unbounded.
        integer: the value must be a whole number (an int, or a float with no fraction).
        finite: refuse NaN and +-infinity (default); with False only NaN is refused.
        why: a reason appended to the expectation (``the report's camera holds 3072``).
    """
    kind = "an integer" if integer else ("a finite number" if finite else "a number")
    expected = kind + _range_text(lo, hi, lo_open, hi_open, unit) + (f" ({why})" if why else "")
    if not is_number(value):
        raise fail(place, expected, value, error=error)
    try:
        f = float(value)
    except OverflowError:  # an int beyond the float range
        raise fail(place, expected, value, error=error) from None
    if math.isnan(f) or (finite and math.isinf(f)):
        raise fail(place, expected, value, error=error)
    if integer and (math.isinf(f) or f != math.floor(f)):
        raise fail(place, expected, value, error=error)
    if lo is not None and (f < lo or (lo_open and f == lo)):
        raise fail(place, expected, value, error=error)
    if hi is not None and (f > hi or (hi_open and f == hi)):
        raise fail(place, expected, value, error=error)
    return f


def optional_number(value: Any, place: str, **kwargs: Any) -> float | None:
    """None for a JSON ``null``, else :func:`number`."""
    return None if value is None else number(value, place, **kwargs)


def integer(value: Any, place: str, *, lo: int | None = None, hi: int | None = None,
            why: str = "", error: ErrorFactory = InputError) -> int:
    """``value`` as an int (a whole number within [lo, hi])."""
    return int(number(value, place, lo=lo, hi=hi, integer=True, why=why, error=error))


def cell(text: str, place: str, *, lo: float | None = None, hi: float | None = None,
         lo_open: bool = False, hi_open: bool = False, integer: bool = False,
         unit: str = "", why: str = "", error: ErrorFactory = InputError) -> float:
    """A number from a CSV cell: decimal text (``1.5``, ``-2e-3``), finite, within range.

    Refuses an empty cell, text, ``nan``, ``inf``, a boolean word, and Python-only spellings
    (``1_000``, ``0x10``).
    """
    stripped = text.strip() if isinstance(text, str) else text
    kind = "an integer" if integer else "a finite number"
    expected = kind + _range_text(lo, hi, lo_open, hi_open, unit) + (f" ({why})" if why else "")
    if not isinstance(stripped, str) or stripped == "" or "_" in stripped:
        raise fail(place, expected, stripped if stripped != "" else "an empty cell",
                   show=True, error=error)
    try:
        value = float(stripped)
    except ValueError:
        raise fail(place, expected, stripped, error=error) from None
    if not math.isfinite(value):
        raise fail(place, expected, stripped, error=error)
    return number(value, place, lo=lo, hi=hi, lo_open=lo_open, hi_open=hi_open, integer=integer,
                  unit=unit, why=why, error=error)


def string(value: Any, place: str, *, choices: Sequence[str] | None = None,
           error: ErrorFactory = InputError) -> str:
    """``value`` if it is a string (one of ``choices`` when given)."""
    if choices is not None:
        expected = "one of " + ", ".join(repr(c) for c in choices)
        if not isinstance(value, str) or value not in choices:
            raise fail(place, expected, value, error=error)
        return value
    if not isinstance(value, str):
        raise fail(place, "a string", value, error=error)
    return value


def string_choice(value: Any, place: str, choices: Sequence[str], *,
                  error: ErrorFactory = InputError) -> str:
    """``value`` if it is one of the strings ``choices``."""
    return string(value, place, choices=choices, error=error)


def mapping(value: Any, place: str, what: str = "a JSON object", *,
            error: ErrorFactory = InputError) -> dict:
    """``value`` if it is a dict (a JSON object)."""
    if not isinstance(value, dict):
        raise fail(place, what, type(value).__name__ if not isinstance(value, (str, int, float))
                   else value, error=error)
    return value


def number_list(value: Any, place: str, *, length: int | None = None,
                min_length: int = 0, lo: float | None = None, hi: float | None = None,
                increasing: bool = False, error: ErrorFactory = InputError) -> list[float]:
    """``value`` if it is a list of finite numbers (of ``length``, each in [lo, hi],
    non-decreasing with ``increasing``)."""
    size = f"{length} " if length is not None else ""
    expected = f"a list of {size}finite numbers" + _range_text(lo, hi, False, False, "")
    if not isinstance(value, list) or (length is not None and len(value) != length) \
            or len(value) < min_length:
        raise fail(place, expected, value, error=error)
    out = [number(v, f"{place}[{i}]", lo=lo, hi=hi, error=error) for i, v in enumerate(value)]
    if increasing and any(b < a for a, b in zip(out, out[1:])):
        raise fail(place, "non-decreasing values (low, high)", value, error=error)
    return out


def unique_names(names: Iterable[str], place: str, what: str = "column", *,
                 error: ErrorFactory = InputError) -> None:
    """Refuse a repeated name (a header with two ``mu_low`` columns: which one is meant?)."""
    seen: set[str] = set()
    for name in names:
        if name in seen:
            raise error(f"{place}: {what} '{name}' appears twice; expected each {what} once "
                        "(which one is meant?)")
        seen.add(name)


def strictly_increasing(values: Sequence[float], place: str, what: str = "time", *,
                        row_name: Callable[[int], str] = lambda i: f"data row {i + 1}",
                        unit: str = "s", error: ErrorFactory = InputError) -> None:
    """Refuse a repeated or decreasing value (duplicate rows, rows out of order)."""
    for i in range(1, len(values)):
        if not values[i] > values[i - 1]:
            raise order_error(place, row_name(i), values[i - 1], values[i], what, unit, error)


def order_error(place: str, row: str, previous: float, value: float, what: str = "time",
                unit: str = "s", error: ErrorFactory = InputError) -> Exception:
    """The error of a ``what`` that does not increase at ``row`` (see :func:`strictly_increasing`)."""
    same = value == previous
    return error(f"{place}, {row}: {what} {float(value)!r} {unit} "
                 f"{'repeats' if same else 'goes back from'} {float(previous)!r} {unit} of the "
                 f"row before; expected strictly increasing {what}s "
                 f"({'a duplicated row?' if same else 'rows out of order?'})")


def json_object(text: str, place: str, what: str = "a JSON object", *,
                error: ErrorFactory = InputError) -> dict:
    """Parse ``text`` as one JSON object, strictly: a key given twice (which value is meant?)
    and the non-standard constants ``NaN`` / ``Infinity`` are refused, naming ``place``."""
    import json

    def pairs(items: list[tuple[str, Any]]) -> dict:
        out: dict = {}
        for key, value in items:
            if key in out:
                raise error(f"{place}: key '{key}' appears twice; expected each key once "
                            "(which value is meant?)")
            out[key] = value
        return out

    def constant(name: str) -> Any:
        raise error(f"{place}: {name} is not JSON; expected a finite number or null")

    try:
        value = json.loads(text, object_pairs_hook=pairs, parse_constant=constant)
    except json.JSONDecodeError as exc:
        raise error(f"{place}: not JSON (line {exc.lineno}, column {exc.colno}: "
                    f"{exc.msg}); expected {what}") from None
    except RecursionError:
        raise error(f"{place}: JSON nested too deeply; expected {what}") from None
    return mapping(value, place, what, error=error)
