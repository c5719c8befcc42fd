"""The native FMUs (issue 21) against the monolithic SciPy reference and the Python FMUs.

    python benchmarks/bench_native_cosim.py [--pairs N] [--steps S]

1. The report's staircase (mu = 2.75e-3, -17 Hz -> -22 Hz in 1 s) co-simulated by our master
   at its default tolerance with the native FMUs, alternating with one SciPy ODE of the same
   closed loop (abu_model.reference) in the same process, N pairs (default 12): median of the
   pair ratios (goal <= 0.3x), of wall time and of process CPU time (``time.process_time``:
   less disturbed by other processes on a loaded machine). The Python FMUs are timed the same
   way, alternating too, for the ratio beside it. The bounds and slip time of native and
   Python runs are printed side by side.
2. FMI call cost per communication step, native vs Python AbuBall through fmpy (the step of
   benchmarks/bench_fmu_calls.py: set 2 inputs, get an FMU state, fmi2DoStep of 1 ms in
   stick, get 5 Reals and 2 Integers, free the state), 7 alternating pairs of S steps
   (default 2000), medians.
FMUs are built and loaded before any timing.
"""
from __future__ import annotations

import argparse
import math
import statistics
import sys
import tempfile
import time
from pathlib import Path

from bench_args import positive_int  # the scripts' folder is on sys.path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from abu_model.params import PlantParams  # noqa: E402
from abu_model.reference import simulate_staircase_reference  # noqa: E402
from bench_fmu_calls import open_fmu, run  # noqa: E402
from fmus.build import build_fmus  # noqa: E402
from fmus.native_build import build_native_fmus  # noqa: E402
from harness.experiments.staircase import StaircaseExperiment, run_staircase  # noqa: E402

HZ = 2.0 * math.pi


def reference(exp: StaircaseExperiment):
    return simulate_staircase_reference(exp.plant, exp.controller, exp.staircase, exp.t_end,
                                        t_start=exp.t_start)


def timed(fn) -> tuple[float, float, object]:
    """(wall time [s], process CPU time [s], result) of fn()."""
    wall, cpu = time.perf_counter(), time.process_time()
    result = fn()
    return time.perf_counter() - wall, time.process_time() - cpu, result


def cosim_ratios(exp, fmus: dict, pairs: int) -> dict:
    """Alternating pairs (co-simulation, reference): the medians of the wall and CPU time
    ratios and of the co-simulation's wall and CPU times [s], and its summary."""
    run_staircase(exp, fmus)  # warm-up: extraction, loading, instances kept for reuse
    reference(exp)
    wall, cpu, t_wall, t_cpu, summary = [], [], [], [], {}
    for _ in range(pairs):
        w_co, c_co, res = timed(lambda: run_staircase(exp, fmus))
        w_ref, c_ref, _ = timed(lambda: reference(exp))
        wall.append(w_co / w_ref)
        cpu.append(c_co / c_ref)
        t_wall.append(w_co)
        t_cpu.append(c_co)
        summary = res.summary
    med = statistics.median
    return {"wall": med(wall), "cpu": med(cpu), "t_wall": med(t_wall), "t_cpu": med(t_cpu),
            "summary": summary}


def call_costs(native: Path, python: Path, tmp: Path, steps: int) -> tuple[float, float, float]:
    """Median per-step cost [us] native, Python, and the median ratio Python / native."""
    a, vr_a = open_fmu(native, tmp / "native")
    b, vr_b = open_fmu(python, tmp / "python")
    pairs, ta, tb = [], 0.0, 0.0
    for _ in range(7):
        x = run(a, vr_a, ta, steps)
        y = run(b, vr_b, tb, steps)
        ta += steps * 1e-3
        tb += steps * 1e-3
        pairs.append((x, y))
    for fmu in (a, b):
        fmu.terminate()
        fmu.freeInstance()
    return (statistics.median(p[0] for p in pairs) * 1e6,
            statistics.median(p[1] for p in pairs) * 1e6,
            statistics.median(p[1] / p[0] for p in pairs))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", type=positive_int, default=12, help="alternating pairs (default 12)")
    ap.add_argument("--steps", type=int, default=2000, help="steps per call-cost run")
    args = ap.parse_args(argv)
    exp = StaircaseExperiment(PlantParams(), -17 * HZ, -22 * HZ)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        native = build_native_fmus(tmp / "native", win64=False)
        python = build_fmus(tmp / "python")
        nat = cosim_ratios(exp, native, args.pairs)
        py = cosim_ratios(exp, python, args.pairs)
        us_nat, us_py, call_ratio = call_costs(native["AbuBall"], python["AbuBall"], tmp,
                                               args.steps)
    print(f"report staircase, default tolerance, {args.pairs} alternating pairs with the SciPy "
          f"reference each:")
    for label, r in (("native FMUs", nat), ("Python FMUs", py)):
        print(f"  {label}: {r['t_wall'] * 1e3:.1f} ms per run ({r['t_cpu'] * 1e3:.1f} ms CPU), "
              f"co-simulation / reference = {r['wall']:.3f}x wall, {r['cpu']:.3f}x CPU time "
              f"(medians{'; goal <= 0.3x' if label.startswith('native') else ''})")
    for label, s in (("native", nat["summary"]), ("python", py["summary"])):
        print(f"  {label}: t_slip {s['t_slip']!r} s, mu_low {s['mu_low']!r}, "
              f"mu_high {s['mu_high']!r}, {s['cosim']['steps']} steps")
    print(f"per communication step through fmpy (set 2, get state, doStep 1 ms in stick, get 5 "
          f"+ 2, free state), AbuBall: native {us_nat:.1f} us, Python {us_py:.1f} us; "
          f"Python / native = {call_ratio:.2f}x (median of 7 alternating pairs of "
          f"{args.steps} steps)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
