"""CPU time of the slip model (:func:`measurement.inference.slip_model.slip_displacement`) in
real analyses: the compiled kernel (``measurement/inference/_slipc.c``) against its NumPy
reference, and the whole analysis with each.

For each seed, a 3072-frame recording of the tracks-level harsh family (the family of
``tests/test_inference.py``: twin drives simulated on the exact plant, camera geometry,
tracking noise, lighting harmonics) is analysed by ``measurement.pipeline.measure_tracks``
while every call of the slip model is recorded (time window, candidates, options). The calls
are then replayed, kernel and NumPy alternated (order swapped every pair), ``--repeat`` pairs;
then the whole ``measure_tracks`` with the kernel and with the NumPy reference, alternated the
same way. CPU time (``time.process_time``), medians: on a machine other people load, the
figure to compare. It also prints the largest difference of the replayed rows (relative to the
call's max |D|).

    nice python benchmarks/bench_slip_model.py [--seeds 1 2 3] [--repeat 7]
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]

import numpy as np  # noqa: E402

from measurement.inference import profile_cache  # noqa: E402
from measurement.inference import slip_model as S  # noqa: E402
from measurement.pipeline import MarkerTracks, measure_tracks  # noqa: E402
from test_inference import scenario_tracks  # noqa: E402

KERNEL = S._slipc


def recorded_calls(tracks: MarkerTracks, l_m: float, d_m: float) -> list[tuple]:
    """(args, kwargs) of every slip-model call of one analysis (kernel in use)."""
    calls: list[tuple] = []
    orig_cache, orig_module = profile_cache.slip_displacement, S.slip_displacement

    def wrap(*a, **k):
        calls.append((a, k))
        return orig_module(*a, **k)
    profile_cache.slip_displacement = S.slip_displacement = wrap
    try:
        measure_tracks(tracks, l_m=l_m, d_m=d_m)
    finally:
        profile_cache.slip_displacement, S.slip_displacement = orig_cache, orig_module
    return calls


def cpu(fn) -> float:
    t0 = time.process_time()
    fn()
    return time.process_time() - t0


def alternated(first, second, repeat: int) -> tuple[list[float], list[float]]:
    """CPU times of ``first`` and ``second``, alternated (order swapped every pair)."""
    a, b = [], []
    for i in range(repeat):
        if i % 2 == 0:
            a.append(cpu(first)); b.append(cpu(second))
        else:
            b.append(cpu(second)); a.append(cpu(first))
    return a, b


def with_kernel(kernel):
    def run(fn):
        def inner():
            S._slipc = kernel
            try:
                fn()
            finally:
                S._slipc = KERNEL
        return inner
    return run


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    ap.add_argument("--repeat", type=int, default=7)
    a = ap.parse_args()
    if KERNEL is None:
        sys.exit("measurement.inference._slipc is not built: run `pip install -e .` (or "
                 "`python setup.py build_ext --inplace`)")
    print(f"slip model in measure_tracks, tracks-level harsh family, 3072 frames, CPU time "
          f"(process_time), median of {a.repeat} alternated pairs:")
    sums = {"kernel": 0.0, "numpy": 0.0, "an_kernel": 0.0, "an_numpy": 0.0}
    for seed in a.seeds:
        times, x, y, ball, _ = scenario_tracks(seed, n_frames=3072)
        tracks = MarkerTracks(times, x, y, np.zeros(x.shape, bool), "synthetic", {})
        calls = recorded_calls(tracks, ball.l, ball.d)
        worst = 0.0
        for args, kw in calls:
            d_c, _ = S.slip_displacement(*args, **kw)
            d_np, _ = S._slip_displacement_numpy(*args, **kw)
            worst = max(worst, float(np.abs(d_c - d_np).max()
                                     / max(np.abs(d_np).max(), 1e-300)))

        def replay_kernel():
            for args, kw in calls:
                S.slip_displacement(*args, **kw)

        def replay_numpy():
            for args, kw in calls:
                S._slip_displacement_numpy(*args, **kw)
        kc, nc = alternated(replay_kernel, replay_numpy, a.repeat)

        def analysis():
            measure_tracks(tracks, l_m=ball.l, d_m=ball.d)
        ak, an = alternated(with_kernel(KERNEL)(analysis), with_kernel(None)(analysis),
                            a.repeat)
        med = {k: statistics.median(v) for k, v in
               (("kernel", kc), ("numpy", nc), ("an_kernel", ak), ("an_numpy", an))}
        for k in sums:
            sums[k] += med[k]
        rows = sum(np.asarray(c[0][3]).size for c in calls)
        sizes = [np.asarray(c[0][0]).size for c in calls]
        print(f"  seed {seed}: {len(calls)} calls, {rows} candidate rows, windows "
              f"{min(sizes)}-{max(sizes)} samples; slip model: kernel {med['kernel']:.4f} s, "
              f"NumPy {med['numpy']:.4f} s ({med['numpy'] / med['kernel']:.1f}x); whole "
              f"analysis: {med['an_kernel']:.3f} s against {med['an_numpy']:.3f} s; rows "
              f"differ by <= {worst:.1e} of max|D|")
    n = len(a.seeds)
    print(f"  mean over seeds: slip model kernel {sums['kernel'] / n:.4f} s, NumPy "
          f"{sums['numpy'] / n:.4f} s ({sums['numpy'] / sums['kernel']:.1f}x); analysis "
          f"{sums['an_kernel'] / n:.3f} s against {sums['an_numpy'] / n:.3f} s "
          f"(-{(sums['an_numpy'] - sums['an_kernel']) / n:.3f} s)")


if __name__ == "__main__":
    main()
