"""Strict JSON text of the measurement results (summaries, meta.json).

NumPy scalars and arrays become Python values and non-finite floats become ``null``, so every
file we write is valid JSON (no ``NaN``) that any reader accepts.
"""
from __future__ import annotations

# The same conversion as the co-simulation results (one definition of what JSON gets).
from abu_model.json_text import dumps, to_jsonable as json_ready  # noqa: F401
