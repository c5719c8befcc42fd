"""Parameter sweeps of the staircase co-simulation as a batch engine on Dask distributed.

Python FMUs loaded into one process share its interpreter and GIL, so a sweep runs one
co-simulation per *process*: a local cluster of worker processes by default, or any running
Dask scheduler (``--scheduler tcp://host:8786``) for sweeps bigger than one machine. The FMUs
are built once into a folder every worker can read; each worker loads them once and resets and
reuses the instances for its next runs (:mod:`harness.cosim.reuse`).

Each run is a :class:`SweepTask`: a key (its grid point, exact) and the full
:class:`~harness.experiments.staircase.StaircaseExperiment`. :func:`run_tasks` keeps a bounded
window of runs in flight (memory does not grow with the grid), hands each finished row to the
:class:`~harness.experiments.sweep_journal.Journal` as it lands (flushed to disk), skips the
runs the journal already holds (resume) and lands each key once (a run recomputed after a
worker died is not duplicated). Dask recomputes the runs of a killed worker.

Result: one row per (mu, omega0) with the bounds, written as CSV (units in the header).
"""
from __future__ import annotations

import itertools
import logging
import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Callable, Iterable, Sequence

from abu_model.errors import AbuError
from abu_model.params import check_finite

from harness.experiments.sweep_journal import COLUMNS, Journal, write_sweep_csv  # noqa: F401

HZ = 2.0 * math.pi
#: Seconds to wait for a Dask scheduler given by address before giving up.
CONNECT_TIMEOUT_S = 5.0


class SchedulerError(AbuError):
    """The Dask scheduler cannot be reached (or its address is malformed)."""


@dataclass(frozen=True)
class SweepPoint:
    """One co-simulation of the sweep: static friction mu [-] and start speed omega0 [Hz]."""

    mu: float
    omega0_hz: float

    @property
    def key(self) -> str:
        """The run's key: its grid point, written exactly."""
        return f"mu={self.mu!r};omega0_hz={self.omega0_hz!r}"


@dataclass(frozen=True)
class SweepTask:
    """One run: its grid point (and key) and the experiment that co-simulates it."""

    point: SweepPoint
    experiment: Any  # StaircaseExperiment (SI units)

    @property
    def key(self) -> str:
        return self.point.key


def sweep_grid(mus: Sequence[float], omega0s_hz: Sequence[float]) -> list[SweepPoint]:
    """Every combination of mu and omega0 (validated: finite numbers; repeats dropped)."""
    if not mus or not omega0s_hz:
        from abu_model.errors import ParameterError
        raise ParameterError("mu" if not mus else "omega0_hz", [], "at least one value")
    points = [SweepPoint(check_finite("mu", m), check_finite("omega0_hz", w))
              for m, w in itertools.product(mus, omega0s_hz)]
    return list(dict.fromkeys(points))


def vary(base, point: SweepPoint, span_hz: float | None = None):
    """``base`` (a StaircaseExperiment) at the point's mu and omega0; the staircase spans
    ``span_hz`` from omega0 (None: base's omega_end - omega0)."""
    plant = replace(base.plant, ball=replace(base.plant.ball, mu=point.mu))
    span = base.omega_end - base.omega0 if span_hz is None else span_hz * HZ
    return replace(base, plant=plant, omega0=point.omega0_hz * HZ,
                   omega_end=point.omega0_hz * HZ + span)


def run_task(task: SweepTask, fmu_dir: str) -> dict:
    """Run one staircase co-simulation (in a worker process); its CSV row."""
    from harness.experiments.staircase import run_staircase  # imported in the worker process

    summary = run_staircase(task.experiment, fmu_dir=Path(fmu_dir)).summary
    slipped = summary["mu_high"] is not None
    return {
        "mu": task.point.mu, "omega0_hz": task.point.omega0_hz, "mu_low": summary["mu_low"],
        "mu_high": summary["mu_high"], "t_slip_s": summary["t_slip"], "slipped": slipped,
        "bracketed": bool(slipped and summary["brackets_mu"]),
    }


def run_point(point: SweepPoint, base, fmu_dir: str) -> dict:
    """Run one point of ``base`` (the span omega_end - omega0 is kept)."""
    return run_task(SweepTask(point, vary(base, point)), fmu_dir)


def connect(scheduler: str | None, workers: int = 2, *,
            timeout_s: float = CONNECT_TIMEOUT_S):
    """A Dask client: to ``scheduler`` (address), or to a new local cluster of ``workers``
    single-threaded processes. Returns (client, cluster or None).

    Raises:
        SchedulerError: the scheduler cannot be reached within ``timeout_s`` or its address
            is malformed (one line, no traceback, nothing logged).
    """
    from dask.distributed import Client, LocalCluster

    quiet_dask()
    if scheduler is None:
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                               dashboard_address=None)
        return Client(cluster), cluster
    try:
        return Client(scheduler, timeout=f"{timeout_s}s"), None
    except Exception as exc:  # noqa: BLE001 - whatever answers there, it is not a scheduler
        why = (str(exc).splitlines() or [""])[0] or type(exc).__name__
        raise SchedulerError(
            f"--scheduler '{scheduler}': no Dask scheduler answered there within {timeout_s:g} s "
            f"({type(exc).__name__}: {why[:160]}); expected the address of a running scheduler "
            "such as tcp://host:8786, or no --scheduler for a local cluster") from None


def quiet_dask() -> None:
    """Dask's own log lines (reconnections, a restarted worker) are not the user's errors."""
    for name in ("distributed", "distributed.client", "distributed.worker", "distributed.nanny",
                 "distributed.scheduler", "distributed.core", "distributed.comm"):
        logging.getLogger(name).setLevel(logging.CRITICAL)


def run_tasks(tasks: Sequence[SweepTask], fmu_dir: Path, client, *,
              journal: Journal | None = None, progress: bool = False,
              window: int | None = None, on_row: Callable[[str, dict], None] | None = None
              ) -> list[dict]:
    """Run every task not yet in ``journal`` on ``client``; rows in the order of ``tasks``.

    At most ``window`` runs are in flight (default: 2 per worker thread + 2), so a grid of any
    size costs bounded memory. Each finished row is appended to the journal before the next is
    taken; ``on_row(key, row)`` is called after it.
    """
    from dask.distributed import as_completed

    done: dict[str, dict] = dict(journal.rows) if journal is not None else {}
    keys = {t.key for t in tasks}
    done = {k: v for k, v in done.items() if k in keys}
    pending = iter([t for t in dict((t.key, t) for t in tasks).values() if t.key not in done])
    if window is None:
        window = 2 * max(1, sum(client.nthreads().values())) + 2
    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=len(keys), initial=len(done), desc="sweep", unit="run")
    prefix = f"abu-sweep-{id(done):x}"

    def submit(task: SweepTask):
        return client.submit(run_task, task, str(fmu_dir), key=f"{prefix}-{task.key}",
                             pure=False)

    flight = as_completed([submit(t) for t in itertools.islice(pending, window)])
    try:
        for future in flight:
            row = future.result()
            key = SweepPoint(row["mu"], row["omega0_hz"]).key
            future.release()
            if key not in done:  # a recomputed run lands once
                if journal is not None:
                    journal.append(key, row)
                done[key] = row
                if on_row is not None:
                    on_row(key, row)
                if bar is not None:
                    bar.update(1)
            nxt = next(pending, None)
            if nxt is not None:
                flight.add(submit(nxt))
    finally:
        if bar is not None:
            bar.close()
    return [done[t.key] for t in tasks]


def run_sweep(points: Iterable[SweepPoint], base, fmu_dir: Path, *, scheduler: str | None = None,
              workers: int = 2, progress: bool = False) -> list[dict]:
    """Run every point of ``base`` (a StaircaseExperiment whose span omega_end - omega0 is
    kept) on a Dask cluster; rows come back in the order of ``points``."""
    tasks = [SweepTask(p, vary(base, p)) for p in points]
    client, cluster = connect(scheduler, workers)
    try:
        return run_tasks(tasks, fmu_dir, client, progress=progress)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
