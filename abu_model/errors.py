"""Error types shared by every package: each names what was wrong and what was expected."""
from __future__ import annotations


class AbuError(Exception):
    """Base class of the toolkit's user-facing errors (bad parameters, bad input files).

    The command line prints the message and exits with status 2.
    """


class ParameterError(AbuError, ValueError):
    """A parameter value is out of its valid range.

    Attributes:
        parameter: the parameter's name as the user spells it (e.g. ``m``, ``te``).
        value: the rejected value.
        expected: what a valid value looks like (e.g. ``"> 0 kg"``).
    """

    def __init__(self, parameter: str, value: object, expected: str):
        self.parameter = parameter
        self.value = value
        self.expected = expected
        super().__init__(f"invalid parameter '{parameter}' = {value!r}: expected {expected}")
