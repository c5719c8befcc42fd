"""Parameter sweeps of the staircase co-simulation on a Dask distributed cluster.

Python FMUs loaded into one process share its interpreter and GIL, so a sweep runs one
co-simulation per *process*: a local cluster of worker processes by default, or any running
Dask scheduler (``--scheduler tcp://host:8786``) for sweeps bigger than one machine. The FMUs
are built once into a folder every worker can read; each worker loads them once and resets and
reuses the instances for its next points (:mod:`harness.cosim.reuse`).

Result: one row per (mu, omega0) with the bounds, written as CSV (units in the header).
"""
from __future__ import annotations

import csv
import io
import itertools
import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Iterable, Sequence

from abu_model.atomic_io import atomic_write_text
from abu_model.params import BallParams, check_finite

HZ = 2.0 * math.pi

#: CSV columns of a sweep, with units.
COLUMNS = ("mu", "omega0_hz", "mu_low", "mu_high", "t_slip_s", "slipped", "bracketed")


@dataclass(frozen=True)
class SweepPoint:
    """One co-simulation of the sweep: static friction mu [-] and start speed omega0 [Hz]."""

    mu: float
    omega0_hz: float


def sweep_grid(mus: Sequence[float], omega0s_hz: Sequence[float]) -> list[SweepPoint]:
    """Every combination of mu and omega0 (validated: finite numbers)."""
    if not mus or not omega0s_hz:
        from abu_model.errors import ParameterError
        raise ParameterError("mu" if not mus else "omega0_hz", [], "at least one value")
    return [SweepPoint(check_finite("mu", m), check_finite("omega0_hz", w))
            for m, w in itertools.product(mus, omega0s_hz)]


def run_point(point: SweepPoint, base, fmu_dir: str) -> dict:
    """Run one staircase co-simulation; ``base`` is the StaircaseExperiment to vary."""
    from harness.experiments.staircase import run_staircase  # imported in the worker process

    plant = replace(base.plant, ball=replace(base.plant.ball, mu=point.mu))
    span = base.omega_end - base.omega0
    exp = replace(base, plant=plant, omega0=point.omega0_hz * HZ,
                  omega_end=point.omega0_hz * HZ + span)
    summary = run_staircase(exp, fmu_dir=Path(fmu_dir)).summary
    slipped = summary["mu_high"] is not None
    return {
        "mu": point.mu, "omega0_hz": point.omega0_hz, "mu_low": summary["mu_low"],
        "mu_high": summary["mu_high"], "t_slip_s": summary["t_slip"], "slipped": slipped,
        "bracketed": bool(slipped and summary["brackets_mu"]),
    }


def run_sweep(points: Iterable[SweepPoint], base, fmu_dir: Path, *, scheduler: str | None = None,
              workers: int = 2, progress: bool = False) -> list[dict]:
    """Run every point on a Dask cluster; rows come back in the order of ``points``.

    Args:
        base: the StaircaseExperiment whose mu and omega0 are varied (the span
            omega_end - omega0 is kept).
        fmu_dir: folder holding the built FMUs (readable by every worker).
        scheduler: address of a running Dask scheduler; None starts a local cluster of
            ``workers`` single-threaded processes.
    """
    from dask.distributed import Client, LocalCluster, as_completed

    points = list(points)
    cluster = None
    if scheduler is None:
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                               dashboard_address=None)
    client = Client(scheduler if scheduler is not None else cluster)
    try:
        futures = [client.submit(run_point, p, base, str(fmu_dir), pure=False) for p in points]
        if progress:
            from tqdm import tqdm
            for _ in tqdm(as_completed(futures), total=len(futures), desc="sweep", unit="run"):
                pass
        return client.gather(futures)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def write_sweep_csv(path: Path, rows: Sequence[dict]) -> None:
    """Write the sweep rows as CSV (atomically)."""
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=COLUMNS, lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({k: ("" if row[k] is None else row[k]) for k in COLUMNS})
    atomic_write_text(path, buffer.getvalue())
