"""Reuse instead of reload: loaded co-simulations kept per system structure.

Loading the three FMUs (extraction is cached, but ``fmi2Instantiate`` of a pythonfmu FMU
imports the slave, appends to ``sys.path`` and builds the Python object) costs about 20 ms
per run and leaves a ``sys.path`` entry behind. Runs of the same structure (table41, sweep
workers, property tests, any batch) instead take a loaded :class:`CoSimulation` from this
pool, ``fmi2Reset`` its instances, set the new parameters and run. pythonfmu 0.7's
``fmi2Reset`` builds a fresh slave object (the old one is released), so nothing of the
previous run survives and ``sys.path`` stays as it is.

A co-simulation whose run failed is freed, not pooled. At most :data:`POOL_SIZE` structures
are kept (least recently used first out); :func:`clear` frees them all (also at exit).
"""
from __future__ import annotations

import atexit
from collections import OrderedDict
from typing import Any

from harness.cosim.master import CoSimulation
from harness.cosim.recording import CoSimResult
from harness.cosim.system import System

#: Loaded co-simulations kept (one per system structure).
POOL_SIZE = 4

_POOL: "OrderedDict[tuple, CoSimulation]" = OrderedDict()


def run_system(system: System, start_time: float, stop_time: float,
               comm_step: float | None = None, *, tol: float | None = None,
               reuse: bool = True, **options: Any) -> CoSimResult:
    """Co-simulate ``system`` over [start_time, stop_time] s, reusing loaded FMUs.

    ``comm_step``, ``tol`` and ``options`` as for :class:`CoSimulation`; ``reuse=False``
    loads, runs and frees as :func:`harness.cosim.master.simulate` does.
    """
    if not reuse:
        with CoSimulation(system, start_time, stop_time, comm_step, tol=tol, **options) as sim:
            return sim.run()
    key = system.structure_key()
    sim = _POOL.pop(key, None)
    if sim is None:
        sim = CoSimulation(system, start_time, stop_time, comm_step, tol=tol, **options)
        sim.__enter__()
    else:
        try:
            sim.set_stepping(comm_step, tol, options.pop("max_step", sim.max_step))
            for name, value in options.items():
                setattr(sim, name, value)
            sim.reuse(system, start_time, stop_time)
        except BaseException:
            sim.close()
            raise
    try:
        result = sim.run()
    except BaseException:
        sim.close()
        raise
    if sim.healthy:
        _POOL[key] = sim
        while len(_POOL) > POOL_SIZE:
            _POOL.popitem(last=False)[1].close()
    else:
        sim.close()
    return result


def clear() -> None:
    """Free every pooled co-simulation."""
    while _POOL:
        _POOL.popitem()[1].close()


def pooled() -> int:
    """Number of loaded co-simulations in the pool."""
    return len(_POOL)


atexit.register(clear)
