"""Co-simulation harness, by job: ``cosim`` (a generic FMI 2.0 master on fmpy that knows nothing
about the ABU), ``experiments`` (the report's staircase, ramp and Table 4.1 described as data on
top of it, their bounds, files and plots, sweeps) and ``planning`` (identify, design, next).
Independent of ``measurement``.
"""
import os

# The toolkit's linear algebra is small (solver steps, local fits): a multi-threaded BLAS is
# slower on it (measured 10-15x on a busy 2-core machine). Respect a user's own setting.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
# The names below load on first use (PEP 562): ``import abu.cli.main`` for ``abu measure`` must
# not pay for fmpy and the master (about 0.1-0.3 s).
_LAZY = {"AlgebraicLoopError": "master", "CoSimResult": "master", "CoSimulation": "master",
         "CoSimulationError": "master", "FMUError": "master", "SwitchEvent": "master",
         "simulate": "master", "Component": "system", "Connection": "system",
         "Source": "system", "System": "system"}


def __getattr__(name: str):
    if name in _LAZY:
        import importlib
        return getattr(importlib.import_module(f".cosim.{_LAZY[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = ["AlgebraicLoopError", "CoSimResult", "CoSimulation", "CoSimulationError", "FMUError",
           "SwitchEvent", "simulate", "Component", "Connection", "Source", "System"]
