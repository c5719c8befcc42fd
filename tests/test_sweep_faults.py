"""``abu sweep`` survives faults (issue 19.4): the real command, killed and restarted.

* SIGKILL of the ``abu sweep`` process at random moments (seeded), then the same command
  again, until it completes: the final CSV holds exactly the rows of an uninterrupted run
  (sorted rows compared as text), the journal never holds a run twice, and it is gone at the
  end.
* SIGKILL of a Dask worker process once the first run has landed: the sweep completes
  (Dask recomputes the lost runs) with the same CSV, each run once.
* A journal of another grid is refused (exit 2, one line naming the journal); ``--overwrite``
  starts afresh.
"""
from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import psutil
import pytest

ROOT = Path(__file__).resolve().parents[1]
#: 24 of the report's staircases (5 Hz down in 1 s) on 2 local workers; some slip.
GRID = ["--mu", "2.75e-3", "3.5e-3", "6e-3", "--omega0-hz", *map(str, range(-15, -23, -1)),
        "--workers", "2"]
RUNS = 24
TIMEOUT_S = 600


def _cmd(out: Path, fmus: Path, *extra: str) -> list[str]:
    return [sys.executable, "-m", "abu.cli.main", "sweep", *GRID, "--out", str(out),
            "--fmu-dir", str(fmus), *extra]


def _env() -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])}


def _start(cmd: list[str]) -> subprocess.Popen:
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=_env(), start_new_session=True)


def _reap(proc: subprocess.Popen, workers: list[psutil.Process]) -> None:
    """After a SIGKILL of the sweep: its orphaned worker processes exit on their own when the
    scheduler is gone; wait for them (and kill the ones still there after 30 s)."""
    proc.communicate()
    gone, alive = psutil.wait_procs(workers, timeout=30)
    for p in alive:
        p.kill()


def _rows(path: Path) -> list[str]:
    lines = path.read_text().splitlines()
    return [lines[0], *sorted(lines[1:])]


def _journal_keys(path: Path) -> list[str]:
    if not path.exists():
        return []
    lines = path.read_text().split("\n")[1:-1]  # header; the last piece may be torn
    keys = []
    for line in lines:
        try:
            keys.append(json.loads(line)["key"])
        except ValueError:
            break
    return keys


@pytest.fixture(scope="module")
def fmus(fmu_dir) -> Path:
    return fmu_dir["AbuBall"].parent


@pytest.fixture(scope="module")
def reference(fmus, tmp_path_factory):
    """The uninterrupted sweep: its sorted rows and its wall time."""
    out = tmp_path_factory.mktemp("reference") / "sweep.csv"
    started = time.perf_counter()
    done = subprocess.run(_cmd(out, fmus), capture_output=True, text=True, env=_env(),
                          timeout=TIMEOUT_S)
    assert done.returncode == 0, done.stderr[-2000:]
    return _rows(out), time.perf_counter() - started


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_sweep_killed_at_random_moments_resumes_to_the_same_csv(fmus, reference, tmp_path,
                                                                seed):
    rng = random.Random(seed)
    rows = reference[0]
    out = tmp_path / "sweep.csv"
    journal = out.with_name("sweep.csv.journal")
    kills, landed = 0, []
    for attempt in range(3):
        proc = _start(_cmd(out, fmus))
        if attempt < 2:  # killed twice at random moments of the sweep, then left to finish
            # after a random number of landed runs (first half, then second half) and a
            # random delay: anywhere in a run, between runs, or while a row is written
            wanted = rng.randrange(0, RUNS // 2) if attempt == 0 else rng.randrange(RUNS // 2,
                                                                                  RUNS)
            delay = rng.uniform(0.0, 0.5)
            workers = []
            while proc.poll() is None and len(_journal_keys(journal)) < wanted:
                try:
                    workers = psutil.Process(proc.pid).children(recursive=True) or workers
                except psutil.NoSuchProcess:
                    break
                time.sleep(0.02)
            time.sleep(delay)
            # not once the final CSV has landed: the sweep's work is then complete, and a kill
            # while the interpreter shuts down Dask (after the journal went) leaves nothing to
            # resume (the same command then refuses the finished CSV; --overwrite redoes it)
            if proc.poll() is None and not out.exists():
                os.kill(proc.pid, signal.SIGKILL)
                kills += 1
                _reap(proc, workers)
                keys = _journal_keys(journal)
                assert len(keys) == len(set(keys)), "a run journalled twice"
                landed.append(len(keys))
                continue
        stdout, stderr = proc.communicate(timeout=TIMEOUT_S)
        assert proc.returncode == 0, stderr[-2000:]
        break
    print(f"\nseed {seed}: {kills} SIGKILLs (runs in the journal at each: {landed}); final: "
          f"{stdout.strip()}")
    assert _rows(out) == rows
    assert not journal.exists()
    assert not [p.name for p in tmp_path.iterdir() if p.name.endswith(".tmp")]


def test_sweep_completes_when_a_worker_is_killed(fmus, reference, tmp_path):
    out = tmp_path / "sweep.csv"
    journal = out.with_name("sweep.csv.journal")
    proc = _start(_cmd(out, fmus))
    killed = None
    deadline = time.monotonic() + TIMEOUT_S
    while proc.poll() is None and time.monotonic() < deadline:
        if len(_journal_keys(journal)) >= 1:  # the first run landed: the others are running
            workers = [p for p in psutil.Process(proc.pid).children(recursive=True)
                       if "spawn_main" in " ".join(p.cmdline())]
            if workers:
                killed = workers[0]
                killed.kill()
                break
        time.sleep(0.02)
    stdout, stderr = proc.communicate(timeout=TIMEOUT_S)
    assert killed is not None, "the sweep ended before a worker could be killed"
    print(f"\nworker {killed.pid} killed after the first run landed; {stdout.strip()}")
    assert proc.returncode == 0, stderr[-2000:]
    assert _rows(out) == reference[0]


def test_a_journal_of_another_grid_is_refused(fmus, tmp_path):
    out = tmp_path / "sweep.csv"
    journal = out.with_name("sweep.csv.journal")
    journal.write_text('{"kind": "abu-sweep-journal", "format_version": 1, '
                       '"settings_sha256": "0", "runs": 3}\n')
    done = subprocess.run(_cmd(out, fmus), capture_output=True, text=True, env=_env(),
                          timeout=TIMEOUT_S)
    assert done.returncode == 2
    assert done.stderr.count("\n") == 1 and str(journal) in done.stderr
    assert "different settings" in done.stderr and not out.exists()
