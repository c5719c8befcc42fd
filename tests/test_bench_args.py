"""The benchmark scripts refuse a count of pairs, runs or repeats below 1 with a clear error
(``--pairs 0`` printed a NaN median before), and accept the smallest valid count."""
from __future__ import annotations

import argparse
import re
import subprocess
import sys
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"
COUNTED = sorted((p.name, opt) for p in BENCHMARKS.glob("bench_*.py")
                 for opt in re.findall(r'add_argument\("(--(?:pairs|runs|repeats))"',
                                       p.read_text()))


def test_every_counted_option_uses_the_positive_type():
    assert len(COUNTED) >= 10
    for name, opt in COUNTED:
        text = (BENCHMARKS / name).read_text()
        assert re.search(rf'add_argument\("{opt}",\s*type=positive_int', text), (name, opt)


@pytest.mark.parametrize("name, opt", COUNTED)
def test_a_count_below_one_is_refused_by_name(name, opt):
    r = subprocess.run([sys.executable, str(BENCHMARKS / name), f"{opt}=0"],
                       capture_output=True, text=True, timeout=120, cwd=BENCHMARKS.parent)
    assert r.returncode == 2
    assert opt in r.stderr and "whole number >= 1" in r.stderr
    assert "Traceback" not in r.stderr


def test_positive_int_itself():
    sys.path.insert(0, str(BENCHMARKS))
    try:
        from bench_args import positive_int
    finally:
        sys.path.remove(str(BENCHMARKS))
    assert positive_int("1") == 1 and positive_int("12") == 12
    for bad in ("0", "-1", "1.5", "", "nan"):
        with pytest.raises(argparse.ArgumentTypeError):
            positive_int(bad)


def _square(x: int) -> int:
    return x * x


def test_map_jobs_keeps_the_order_in_one_process_and_in_a_pool():
    sys.path.insert(0, str(BENCHMARKS))
    try:
        from bench_args import map_jobs
    finally:
        sys.path.remove(str(BENCHMARKS))
    want = [x * x for x in range(7)]
    assert map_jobs(_square, range(7), 1) == want
    assert map_jobs(_square, range(7), 2) == want
    assert map_jobs(_square, [], 2) == []
