"""Reading one JSON object from a file for the controller's file schemas (``drive.json``,
``profile.json``), standard library only (the schemas may be vendored into an FMU).

Strict where :mod:`abu_model.validate` is present (a key given twice, NaN or Infinity refused),
plain ``json`` otherwise. Every failure is ``error(source, message)``: the schema's own error
type, which names the file.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Callable

try:
    from abu_model.validate import json_object as _json_object
except ImportError:  # pragma: no cover - only without abu_model
    _json_object = None


def read_json_object(path: str | Path, expected: str,
                     error: Callable[[str, str], Exception]) -> tuple[Any, str]:
    """(the parsed object, the source name) of the JSON file ``path``.

    Args:
        expected: what the file should be, for the messages (``a JSON object (a drive.json
            of 'abu identify')``).
        error: the schema's error type, called as ``error(source, message)``.
    """
    p = Path(path)
    source = str(p)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise error(source, f"cannot be read ({exc.strerror or exc})") from None
    except UnicodeDecodeError:
        raise error(source, f"is not UTF-8 text (expected {expected})") from None
    if _json_object is not None:  # strict: a key given twice, NaN or Infinity refused
        return _json_object(text, source, expected,
                            error=lambda m: error(source, m.split(": ", 1)[1])), source
    try:
        return json.loads(text), source
    except json.JSONDecodeError as exc:
        raise error(source, f"is not valid JSON (line {exc.lineno}: {exc.msg})") from None
