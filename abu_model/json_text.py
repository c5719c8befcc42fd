"""Strict JSON text of results: every file we write is valid JSON (no ``NaN``) that any reader
accepts. One definition for the co-simulation and the measurement side.

Standard library only (numpy values are converted through their ``tolist``), like the rest of
``abu_model``.
"""
from __future__ import annotations

import json
import math
from typing import Any, Mapping


def to_jsonable(value: Any) -> Any:
    """numpy scalars/arrays to Python; non-finite floats to None (JSON has no NaN/inf)."""
    if isinstance(value, Mapping):
        return {str(k): to_jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [to_jsonable(v) for v in value]
    if hasattr(value, "tolist") and not isinstance(value, (str, bytes)):  # numpy array/scalar
        return to_jsonable(value.tolist())
    if isinstance(value, bool):
        return value
    if isinstance(value, int):
        return int(value)
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    return value


def dumps(obj: Any) -> str:
    """Strict JSON text (no NaN) of ``obj``, indented, with a final newline."""
    return json.dumps(to_jsonable(obj), indent=2, allow_nan=False) + "\n"
