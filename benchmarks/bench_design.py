"""Speed of ``abu design`` (the issue's target: under 10 s) against one co-simulation, same run.

    nice python benchmarks/bench_design.py [--pairs N]

For three prior ranges (the report's [2.75e-3, 6 x 2.75e-3] with the report's loop, [0.02, 0.04]
and [0.008, 0.05] with lagged drives) it times, alternately, the design (search with the
closed-form loop response, then the co-simulation check at the range's two ends, as ``abu
design`` does) and its peer: one co-simulation of the report's staircase (-17 Hz -> -22 Hz in
1 s, 1.55 s simulated). Prints the medians over the pairs, the ratio design / co-simulation,
and the search alone. FMUs are built once before timing.
"""
from __future__ import annotations

import argparse
import math
import statistics
import sys
import tempfile
import time

from bench_args import positive_int  # the scripts' folder is on sys.path

from abu_model.params import PlantParams
from controller.drive import Drive
from fmus.build import build_fmus
from harness.planning.design import DesignSpec, design_staircase
from harness.planning.design_check import check_design
from harness.experiments.staircase import StaircaseExperiment, run_staircase

HZ = 2.0 * math.pi
CASES = [((2.75e-3, 6 * 2.75e-3), Drive()),
         ((0.02, 0.04), Drive("pi-lag", 0.7, 12.0, 0.02)),
         ((0.008, 0.05), Drive("pi-lag", 0.6, 8.0, 0.01))]
TARGET_S = 10.0


def _timed(fn):
    start = time.perf_counter()
    result = fn()
    return time.perf_counter() - start, result


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pairs", type=positive_int, default=3, help="timed pairs per range (default 3)")
    args = parser.parse_args(argv)
    peer_exp = StaircaseExperiment(PlantParams(), -17 * HZ, -22 * HZ)
    worst = 0.0
    with tempfile.TemporaryDirectory() as tmp:
        fmus = build_fmus(tmp)
        run_staircase(peer_exp, fmus)  # warm-up: extraction, imports
        for (lo, hi), drive in CASES:
            spec = DesignSpec(lo, hi, drive=drive)
            t_design, t_search, t_peer = [], [], []
            for _ in range(args.pairs):
                ts, design = _timed(lambda: design_staircase(spec))
                tc, _ = _timed(lambda: check_design(design, fmu_dir=fmus))
                t_search.append(ts)
                t_design.append(ts + tc)
                t_peer.append(_timed(lambda: run_staircase(peer_exp, fmus))[0])
            d, s, p = (statistics.median(x) for x in (t_design, t_search, t_peer))
            worst = max(worst, d)
            print(f"mu in [{lo:.4g}, {hi:.4g}], drive zeta {drive.zeta} omega_n {drive.omega_n} "
                  f"rad/s tau {drive.tau_motor} s: design {d:.2f} s (search {s:.2f} s + "
                  f"co-simulation check {d - s:.2f} s), one report co-simulation {p:.2f} s; "
                  f"ratio design / co-simulation {d / p:.1f} (median of {args.pairs} pairs)")
    print(f"slowest design {worst:.2f} s: {'under' if worst < TARGET_S else 'OVER'} the "
          f"{TARGET_S:g} s target")
    return 0 if worst < TARGET_S else 1


if __name__ == "__main__":
    sys.exit(main())
