"""``abu sweep`` (Dask batch engine) against a plain loop of ``abu simulate`` processes.

    python benchmarks/bench_sweep.py [--pairs P] [--runs N] [--memory-runs M] [--budget-s B]

Grid: cheap short staircases (1 Hz down from omega0 over a 0.2 s sine, simulated to 0.3 s),
mu in 2.75e-3 .. 6e-3, omega0 from -15 Hz down.

1. Throughput: one ``abu sweep --workers 1`` over N runs (default 24) and, alternating with
   it, a plain loop of N ``abu simulate`` processes (same options, one process per run), P
   pairs (default 3). Both are timed by the wall clock and by the CPU time of the process
   tree (resource.getrusage(RUSAGE_CHILDREN): the machine is shared, wall times are noisy).
   Printed: runs per second per worker of each, and the median of the pair ratios.
2. Memory: M runs (default 10,000) through the library on a local cluster of 2 workers with
   the journal on, the resident memory (RSS) of the client + scheduler process and of each
   worker sampled every 500 runs; stops early after B seconds (default 1200) and then says
   how far it got. Printed: RSS at the start and end and the growth per run.
"""
from __future__ import annotations

import argparse
import math
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench_args import positive_int  # the scripts' folder is on sys.path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

MUS = ["2.75e-3", "3.5e-3", "6e-3"]
SHORT = ["--te", "0.2", "--t-end", "0.3"]


def _omegas(n: int) -> list[str]:
    return [str(-15 - k) for k in range(math.ceil(n / len(MUS)))]


def _grid(n: int) -> list[tuple[str, str]]:
    return [(mu, w) for w in _omegas(n) for mu in MUS][:n]


def _env() -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": str(ROOT)}


def _timed(commands: list[list[str]]) -> tuple[float, float]:
    """(wall s, CPU s of the children) of running the commands one after another."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    for cmd in commands:
        subprocess.run(cmd, check=True, env=_env(), stdout=subprocess.DEVNULL)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return time.perf_counter() - started, cpu


def throughput(pairs: int, runs: int, fmus: Path, work: Path) -> None:
    grid = _grid(runs)
    abu = [sys.executable, "-m", "abu.cli.main"]
    omegas = sorted({w for _, w in grid}, key=float, reverse=True)
    sweep_rows, loop_rows = [], []
    for k in range(pairs):
        out = work / f"sweep{k}.csv"
        sweep = [abu + ["sweep", "--mu", *MUS, "--omega0-hz", *omegas, "--span-hz", "-1",
                        *SHORT, "--workers", "1", "--fmu-dir", str(fmus), "--out", str(out)]]
        loop = [abu + ["simulate", "--mu", mu, "--omega0-hz", w,
                       "--omega-end-hz", str(float(w) - 1), *SHORT, "--fmu-dir", str(fmus)]
                for mu, w in grid]
        n_sweep = len(MUS) * len(omegas)
        for name, cmds, rows, n in (("sweep", sweep, sweep_rows, n_sweep),
                                    ("loop", loop, loop_rows, len(grid)))[::1 if k % 2 == 0
                                                                          else -1]:
            wall, cpu = _timed(cmds)
            rows.append((n / wall, n / cpu))
            print(f"pair {k + 1}: {name:5s} {n} runs: wall {wall:6.2f} s "
                  f"({n / wall:6.2f} runs/s/worker), CPU {cpu:6.2f} s ({n / cpu:6.2f} runs per "
                  "CPU-second)", flush=True)
    for i, what in ((0, "wall-clock runs/s per worker"), (1, "runs per CPU-second")):
        ratios = [s[i] / p[i] for s, p in zip(sweep_rows, loop_rows)]
        print(f"{what}: sweep median {statistics.median(r[i] for r in sweep_rows):.2f}, "
              f"abu simulate loop median {statistics.median(r[i] for r in loop_rows):.3f}; "
              f"median pair ratio {statistics.median(ratios):.1f}x ({pairs} pairs)")


def memory(runs: int, budget_s: float, fmus: Path, work: Path) -> None:
    import psutil

    from abu.cli.main import build_parser
    from abu.cli.sweep import sweep_tasks
    from harness.experiments.sweep import connect, run_tasks
    from harness.experiments.sweep_journal import Journal, settings_hash

    n_w = math.ceil(runs / len(MUS))
    # omega0 from -15 Hz down in steps small enough for the grid to stay within 200 Hz
    omegas = [f"{-15 - 150 * k / n_w:.6f}" for k in range(n_w)]
    args = build_parser().parse_args(["sweep", "--mu", *MUS, "--omega0-hz", *omegas,
                                      "--span-hz", "-1", *SHORT, "--out", "x.csv"])
    tasks = sweep_tasks(args)[:runs]
    journal = Journal(work / "memory.csv.journal",
                      settings_hash((t.key, t.experiment) for t in tasks), len(tasks))
    client, cluster = connect(None, 2)
    me = psutil.Process()
    samples = []
    started = time.perf_counter()

    def rss_mb() -> tuple[float, float]:
        workers = [psutil.Process(p.pid) for p in me.children(recursive=True)
                   if "spawn_main" in " ".join(p.cmdline())]
        return me.memory_info().rss / 2**20, sum(w.memory_info().rss for w in workers) / 2**20

    def on_row(key, row):
        done = len(journal.rows)
        if done % 500 == 0 or done == 1:
            client_mb, workers_mb = rss_mb()
            samples.append((done, client_mb, workers_mb))
            print(f"{done:6d} runs, {time.perf_counter() - started:7.1f} s: RSS client + "
                  f"scheduler {client_mb:7.1f} MB, workers {workers_mb:7.1f} MB", flush=True)
        if time.perf_counter() - started > budget_s:
            raise TimeoutError

    try:
        run_tasks(tasks, fmus, client, journal=journal, on_row=on_row)
        finished = True
    except TimeoutError:
        finished = False
    finally:
        journal.close()
        client.close()
        cluster.close()
    (n0, c0, w0), (n1, c1, w1) = samples[0], samples[-1]
    how = (f"all {runs} runs" if finished else
           f"stopped after {len(journal.rows)} of {runs} runs (budget {budget_s:g} s)")
    print(f"memory, {how}: client + scheduler {c0:.1f} -> {c1:.1f} MB, workers {w0:.1f} -> "
          f"{w1:.1f} MB between run {n0} and run {n1}: growth "
          f"{1024 * (c1 - c0) / max(1, n1 - n0):.2f} KB/run (client + scheduler), "
          f"{1024 * (w1 - w0) / max(1, n1 - n0):.2f} KB/run (2 workers)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--pairs", type=positive_int, default=3)
    parser.add_argument("--runs", type=positive_int, default=24)
    parser.add_argument("--memory-runs", type=int, default=10_000)
    parser.add_argument("--budget-s", type=float, default=1200.0)
    parser.add_argument("--skip-throughput", action="store_true")
    opts = parser.parse_args()
    from fmus.build import build_fmus

    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        build_fmus(work / "fmus")
        if not opts.skip_throughput:
            throughput(opts.pairs, opts.runs, work / "fmus", work)
        if opts.memory_runs:
            memory(opts.memory_runs, opts.budget_s, work / "fmus", work)


if __name__ == "__main__":
    main()
