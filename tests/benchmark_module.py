"""Import a script of ``benchmarks/`` in a test, as it runs as a script (its folder on sys.path
while the module's tests run)."""
import importlib.util
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


def benchmark_module(name: str):
    """Generator for a module-scoped fixture: ``yield from benchmark_module("bench_x")``."""
    mp = pytest.MonkeyPatch()
    mp.syspath_prepend(str(BENCHMARKS))
    spec = importlib.util.spec_from_file_location(name, BENCHMARKS / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    yield mod
    mp.undo()
