"""Strict JSON text of the measurement results (summaries, meta.json).

NumPy scalars and arrays become Python values and non-finite floats become ``null``, so every
file we write is valid JSON (no ``NaN``) that any reader accepts.
"""
from __future__ import annotations

import json
import math
from typing import Any

import numpy as np


def json_ready(obj: Any) -> Any:
    """Replace non-finite floats by None and NumPy scalars/arrays by Python values."""
    if isinstance(obj, dict):
        return {str(k): json_ready(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_ready(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return json_ready(obj.tolist())
    if isinstance(obj, (np.floating, float)):
        f = float(obj)
        return f if math.isfinite(f) else None
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    return obj


def dumps(obj: Any) -> str:
    """Strict JSON text (no NaN) of ``obj``, indented, with a final newline."""
    return json.dumps(json_ready(obj), indent=2, allow_nan=False) + "\n"
