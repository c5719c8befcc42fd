"""Strict JSON text of the measurement results (summaries, meta.json).

NumPy scalars and arrays become Python values and non-finite floats become ``null``, so every
file we write is valid JSON (no ``NaN``) that any reader accepts.
"""
from __future__ import annotations

import json
from typing import Any

# The same conversion as the co-simulation results (one definition of what JSON gets).
from harness.results_io import to_jsonable as json_ready


def dumps(obj: Any) -> str:
    """Strict JSON text (no NaN) of ``obj``, indented, with a final newline."""
    return json.dumps(json_ready(obj), indent=2, allow_nan=False) + "\n"
