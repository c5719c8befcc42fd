"""Output folders are units: SIGKILL at random moments, SIGTERM, and two runs into one --out.

* ``abu render`` and ``abu measure`` are killed (SIGKILL) at random moments, 20 times in all;
  after each kill the output folder is absent or complete and self-consistent (frame count of
  frames.tif = meta.json = truth.csv rows; tracks.csv rows = kinematics.csv rows = the summary's
  frame count), and after the next run no temporary file, lock or per-run temporary folder is
  left (beside the output nor in the system temporary folder).
* Two ``abu simulate`` into one ``--out`` started together: one refuses with a clear message,
  the other's output is complete.
"""
from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent
RENDER_FRAMES = 200


def _env(tmp_base: Path) -> dict[str, str]:
    env = dict(os.environ)
    # A private system temporary folder: the per-run folders of these processes only.
    env["TMPDIR"] = str(tmp_base)
    env["ABU_SYSTEM_TMPDIR"] = str(tmp_base)
    env["OPENBLAS_NUM_THREADS"] = "1"
    return env


def _abu(args: list[str], env: dict[str, str]) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "abu.cli.main", *args], cwd=ROOT, env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)


def _rows(path: Path) -> int:
    with open(path, newline="") as handle:
        lines = [r for r in csv.reader(handle) if r and not r[0].startswith("#")]
    return len(lines) - 1  # header


def _check_render(out: Path) -> None:
    """Complete and self-consistent, or absent."""
    if not out.exists():
        return
    import tifffile
    assert sorted(p.name for p in out.iterdir()) == ["frames.tif", "meta.json", "truth.csv"]
    meta = json.loads((out / "meta.json").read_text())
    with tifffile.TiffFile(out / "frames.tif") as tif:
        frames = tif.asarray()
    assert frames.shape[0] == meta["n_frames"] == _rows(out / "truth.csv")


def _check_measure(out: Path) -> None:
    if not out.exists():
        return
    names = sorted(p.name for p in out.iterdir())
    assert names == ["kinematics.csv", "summary.json", "tracks.csv"], names
    summary = json.loads((out / "summary.json").read_text())
    assert summary["kind"] == "abu-measure-summary"
    n = summary["input"]["frames"]
    assert _rows(out / "tracks.csv") == _rows(out / "kinematics.csv") == n


def _leftovers(folder: Path, name: str) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.startswith(f".{name}."))


def _run_dirs(tmp_base: Path) -> list[str]:
    return sorted(p.name for p in tmp_base.glob("abu-run-*"))


@pytest.fixture(scope="module")
def twin(fmu_dir, tmp_path_factory) -> Path:
    base = tmp_path_factory.mktemp("kill_twin")
    out = base / "twin"
    proc = subprocess.run([sys.executable, "-m", "abu.cli.main", "render", "--out", str(out),
                           "--frames", "1500", "--quiet", "--fmu-dir", _fmu_folder(fmu_dir)], cwd=ROOT, env=_env(base),
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    return out


def _kill_loop(args_of, check, out: Path, tmp_base: Path, kills: int, seed: int) -> list[float]:
    env = _env(tmp_base)
    # One complete run first: how long a run takes, so the kills fall anywhere in it.
    start = time.perf_counter()
    proc = _abu(args_of(0), env)
    assert proc.wait(timeout=300) == 0, proc.stderr.read()
    duration = time.perf_counter() - start
    check(out)
    rng = np.random.default_rng(seed)
    moments = []
    for i in range(1, kills + 1):
        moment = float(rng.uniform(0.0, duration))
        proc = _abu(args_of(i), env)
        time.sleep(moment)
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=60)
        proc.stderr.close()
        moments.append(moment)
        check(out)  # absent or complete, never a mixture
    # The next run cleans what the killed ones left and leaves nothing itself.
    proc = _abu(args_of(kills + 1), env)
    assert proc.wait(timeout=300) == 0, proc.stderr.read()
    proc.stderr.close()
    check(out)
    assert out.exists()
    assert _leftovers(out.parent, out.name) == []
    assert [p.name for p in out.rglob(".*")] == []
    assert _run_dirs(tmp_base) == []
    return moments


def _fmu_folder(fmu_dir) -> str:
    return str(Path(next(iter(fmu_dir.values()))).parent)


def test_sigkill_render_at_random_moments(fmu_dir, tmp_path):
    out = tmp_path / "render"
    tmp_base = tmp_path / "systmp"
    tmp_base.mkdir()

    def args_of(i: int) -> list[str]:
        # a different frame count each run: a mixture of two runs would not be consistent
        return ["render", "--out", str(out), "--frames", str(RENDER_FRAMES + 7 * i),
                "--seed", str(i), "--quiet", "--overwrite", "--fmu-dir", _fmu_folder(fmu_dir)]

    moments = _kill_loop(args_of, _check_render, out, tmp_base, kills=8, seed=1)
    print(f"\nrender killed at {', '.join(f'{m:.2f}' for m in moments)} s")


def test_sigkill_measure_at_random_moments(twin, tmp_path):
    out = tmp_path / "measure"
    tmp_base = tmp_path / "systmp"
    tmp_base.mkdir()

    def args_of(i: int) -> list[str]:
        return ["measure", str(twin), "--out", str(out), "--no-plots", "--mc-draws", str(i % 3),
                "--quiet", "--overwrite"]

    moments = _kill_loop(args_of, _check_measure, out, tmp_base, kills=12, seed=2)
    print(f"\nmeasure killed at {', '.join(f'{m:.2f}' for m in moments)} s")


def test_sigterm_leaves_nothing(fmu_dir, tmp_path):
    out = tmp_path / "render"
    tmp_base = tmp_path / "systmp"
    tmp_base.mkdir()
    proc = _abu(["render", "--out", str(out), "--frames", "3072", "--quiet", "--fmu-dir",
                 _fmu_folder(fmu_dir)], _env(tmp_base))
    time.sleep(1.5)
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(timeout=60) == 128 + signal.SIGTERM
    proc.stderr.close()
    assert not out.exists()
    assert list(tmp_path.glob(".render*")) == [] and _run_dirs(tmp_base) == []


def test_two_runs_into_one_out(fmu_dir, tmp_path):
    out = tmp_path / "sim"
    tmp_base = tmp_path / "systmp"
    tmp_base.mkdir()
    env = _env(tmp_base)
    folder = _fmu_folder(fmu_dir)
    args = ["simulate", "--out", str(out), "--fmu-dir", folder, "--te", "0.5",
            "--omega-end-hz", "-19"]
    procs = [_abu(args, env) for _ in range(2)]
    codes = [p.wait(timeout=300) for p in procs]
    errors = [p.stderr.read() for p in procs]
    for p in procs:
        p.stderr.close()
    assert sorted(codes) == [0, 2], (codes, errors)
    refused = errors[codes.index(2)].strip().splitlines()
    assert len(refused) == 1 and str(out) in refused[0]
    assert "another abu run" in refused[0] or "--overwrite" in refused[0]
    names = sorted(p.name for p in out.iterdir())
    assert "result.csv" in names and "summary.json" in names
    summary = json.loads((out / "summary.json").read_text())
    assert summary["kind"] == "abu-simulate-summary"
    assert _rows(out / "result.csv") > 10 and summary["mu_low"] > 0
    assert _leftovers(tmp_path, "sim") == [] and _run_dirs(tmp_base) == []


def test_swapped_seed_roles_are_refused(twin, tmp_path, capsys):
    """The recording measured with the CD and ball seeds swapped: an error, not a number."""
    from abu.cli.main import main

    meta = json.loads((twin / "meta.json").read_text())
    centre, cd, ball = meta["seeds"].split(";")
    out = tmp_path / "m"
    assert main(["measure", str(twin), "--out", str(out), "--no-plots", "--mc-draws", "0",
                 "--quiet", "--seeds", f"{centre};{ball};{cd}"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "swapped" in err[0] and "--seeds" in err[0]
    assert not out.exists()
    assert main(["measure", str(twin), "--out", str(out), "--no-plots", "--mc-draws", "0",
                 "--quiet", "--seeds", meta["seeds"]]) == 0
