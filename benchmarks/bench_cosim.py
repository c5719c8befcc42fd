"""Speed of the staircase co-simulation against the monolithic SciPy reference, same run.

    python benchmarks/bench_cosim.py [--repeat N] [--comm-step S]

Runs the report's staircase experiment (mu = 2.75e-3, -17 Hz -> -22 Hz in 1 s, integral PI)
both ways and prints the median wall time of each, the ratio co-simulation / reference, the
time per communication step, and how far the bounds agree. FMUs are built once before timing.
"""
from __future__ import annotations

import argparse
import math
import statistics
import sys
import tempfile
import time

from abu_model.params import PlantParams
from abu_model.reference import simulate_staircase_reference
from fmus.build import build_fmus
from harness.experiments import StaircaseExperiment, run_staircase

HZ = 2.0 * math.pi


def _median_time(fn, repeat: int):
    times, result = [], None
    for _ in range(repeat):
        start = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times), result


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3, help="timed runs of each (default 3)")
    parser.add_argument("--comm-step", type=float, default=1e-3, help="communication step [s]")
    parser.add_argument("--theta-ref", choices=["integral", "thesis"], default="integral")
    args = parser.parse_args(argv)

    exp = StaircaseExperiment(PlantParams(), -17 * HZ, -22 * HZ, comm_step=args.comm_step,
                              theta_ref_mode=args.theta_ref)
    with tempfile.TemporaryDirectory() as tmp:
        fmus = build_fmus(tmp)
        run_staircase(exp, fmus)  # warm-up: extraction, imports
        t_cosim, cosim = _median_time(lambda: run_staircase(exp, fmus), args.repeat)
    t_ref, ref = _median_time(
        lambda: simulate_staircase_reference(exp.plant, exp.controller, exp.staircase, exp.t_end,
                                             t_start=exp.t_start), args.repeat)
    stats = cosim.summary["cosim"]
    s = cosim.summary
    print(f"staircase experiment, {args.theta_ref} PI, {exp.t_end - exp.t_start:g} s simulated, "
          f"communication step {args.comm_step:g} s")
    print(f"co-simulation (FMUs + master): {t_cosim:.3f} s median of {args.repeat} "
          f"({stats['steps']} steps, {stats['rollbacks']} rollbacks, "
          f"{1e6 * t_cosim / stats['steps']:.0f} us per step)")
    print(f"monolithic reference (SciPy):  {t_ref:.3f} s median of {args.repeat}")
    print(f"ratio co-simulation / reference: {t_cosim / t_ref:.1f}")
    print(f"mu_low  co-sim {s['mu_low']:.6e}  reference {ref.mu_low:.6e}  "
          f"rel. diff {s['mu_low'] / ref.mu_low - 1:+.2e} [-]")
    if ref.mu_high is not None and s["mu_high"] is not None:
        print(f"mu_high co-sim {s['mu_high']:.6e}  reference {ref.mu_high:.6e}  "
              f"rel. diff {s['mu_high'] / ref.mu_high - 1:+.2e} [-]")
        print(f"t_slip  co-sim {s['t_slip']:.9f} s  reference {ref.t_slip:.9f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
