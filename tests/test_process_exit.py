"""The ``abu`` program's fast exit (:mod:`abu.cli.process_exit`): what a normal exit does that
matters still happens: the status, every byte of buffered output, the ``atexit`` handlers, a
running non-daemon thread's end. (What the skipped teardown costs is printed by
``benchmarks/bench_measure.py``.)"""
from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _run(code: str, tmp_path: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize("status", [0, 2, 7])
def test_status_output_and_exit_handlers_survive(tmp_path, status):
    code = f"""
        import atexit, sys
        from pathlib import Path
        from abu.cli.process_exit import exit_process
        atexit.register(lambda: Path("handler_ran").write_text("yes"))
        sys.stdout.write("x" * 100000)            # buffered in a pipe, never flushed by hand
        sys.stderr.write("last words")
        exit_process({status})
        Path("after_exit").write_text("never")
        """
    proc = _run(code, tmp_path)
    assert proc.returncode == status
    assert proc.stdout == "x" * 100000 and proc.stderr == "last words"
    assert (tmp_path / "handler_ran").read_text() == "yes"
    assert not (tmp_path / "after_exit").exists()


def test_waits_for_a_running_non_daemon_thread(tmp_path):
    code = """
        import threading, time
        from pathlib import Path
        from abu.cli.process_exit import exit_process
        def work():
            time.sleep(0.3)
            Path("thread_done").write_text("yes")
        threading.Thread(target=work).start()
        exit_process(3)
        """
    proc = _run(code, tmp_path)
    assert proc.returncode == 3
    assert (tmp_path / "thread_done").read_text() == "yes"


def test_abu_program_keeps_its_status_and_message(tmp_path):
    """The installed program's way in (``python -m abu.cli.main`` runs the same function): a
    user error still exits 2 with its one-line message, a success 0 with its output."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    bad = subprocess.run([sys.executable, "-m", "abu.cli.main", "measure",
                          str(tmp_path / "missing.tif"), "--out", str(tmp_path / "o")],
                         capture_output=True, text=True, env=env, timeout=120)
    assert bad.returncode == 2
    assert "missing.tif" in bad.stderr and "Traceback" not in bad.stderr
    ok = subprocess.run([sys.executable, "-m", "abu.cli.main", "--help"],
                        capture_output=True, text=True, env=env, timeout=120)
    assert ok.returncode == 0 and "measure" in ok.stdout
