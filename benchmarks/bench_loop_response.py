"""The closed loop's response per call: the compiled kernel (``abu_model/_loopc.c``, what
``loop_response.response`` runs) against its NumPy reference (``_response_numpy``), timed in
the same process, alternated.

Each call is what the drive-model fits make thousands of times a record: a staircase of 10
steps of 1 Hz, the loop with lag and setpoint filter (four poles), the record's frames (800:
the staircase search's every third frame; 3072: a whole recording at 4500 frames/s), theta
included. The poles and residues are computed once (``modes`` is cached), so the figure is
the response alone. Printed: the median time per call of each over ``--pairs`` alternated
pairs of ``--calls`` calls, and the median ratio.

    python benchmarks/bench_loop_response.py [--pairs 7] [--calls 300]
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

from bench_args import positive_int  # the scripts' folder is on sys.path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from abu_model import loop_response as L  # noqa: E402


def _per_call(fn, calls: int) -> float:
    start = time.process_time()
    for _ in range(calls):
        fn()
    return (time.process_time() - start) / calls


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--pairs", type=positive_int, default=7)
    ap.add_argument("--calls", type=int, default=300)
    args = ap.parse_args(argv)
    if L._loopc is None:
        print("abu_model._loopc is not built (pip install -e . with a C compiler)")
        return 1
    loop = (0.7, 20.0, 0.006, 0.8, 0.004)
    sp = L.Setpoints(tuple(np.linspace(0.05, 0.55, 10)), tuple(-60.0 - 2 * np.pi * np.arange(11)))
    poles, res = L.modes(*loop)
    for frames in (800, 3072):
        t = np.arange(frames) / 4500.0
        kernel = (lambda: L.response(sp, t, *loop[:4], True, setpoint_tau=loop[4]))
        numpy_ = (lambda: L._response_numpy(sp, t, poles, res, True))
        k_times, n_times = [], []
        for _ in range(args.pairs):
            k_times.append(_per_call(kernel, args.calls))
            n_times.append(_per_call(numpy_, args.calls))
        ratio = statistics.median(n / k for n, k in zip(n_times, k_times))
        print(f"{frames} frames: kernel {1e6 * statistics.median(k_times):.0f} us a call, "
              f"NumPy {1e6 * statistics.median(n_times):.0f} us; the kernel {ratio:.1f}x "
              f"faster (median of {args.pairs} alternated pairs of {args.calls} calls, CPU)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
