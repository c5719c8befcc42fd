"""Command-line types and the worker pool shared by the benchmark scripts."""
from __future__ import annotations

import argparse
from multiprocessing import Pool
from typing import Callable, Iterable


def positive_int(text: str) -> int:
    """An argparse type: a whole number >= 1 (pairs, runs, repeats: a median of none is no
    figure)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 1, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 1, got {value}")
    return value


def map_jobs(fn: Callable, items: Iterable, jobs: int) -> list:
    """``[fn(x) for x in items]``, in ``jobs`` worker processes when more than one (one item
    a task, in order); the pool is closed and joined, not terminated (a terminated worker
    running ``abu`` would print that it was)."""
    items = list(items)
    if jobs <= 1:
        return [fn(x) for x in items]
    pool = Pool(jobs)
    try:
        return pool.map(fn, items, chunksize=1)
    finally:
        pool.close()
        pool.join()
