"""Two limits of ``abu measure --kinematics drive-model --find-staircase``, with the figures
docs/measurement-analysis.md ("Seventeenth session") quotes:

* ``--steps N [N ...]``: the search on true staircases of N steps of 1 Hz (3000 frames/s,
  0.68 s, twin's digital PI drive at the frame rate), each in a fresh process: CPU [s], peak
  resident memory [GB] and whether the drive's count was found. Step 4's assignment box
  grows as the square of the step count, hence ``staircase_search.MAX_STEPS``.
* ``--cogging``: a torque ripple of ``--amp`` rad/s^2 at ``--order`` per turn added to
  the staircase records of tests/test_staircase_search.py (seeds ``--first`` ..): for the
  loop fitted over the stated staircase, the staircase search and Savitzky-Golay (42 ms,
  degree 9), accepted or not and the share of check times whose 95 % bar holds the true
  omega_dot. A ripple below a frame's noise passes every kinematics (an open limit).

Run::

    python benchmarks/bench_search_limits.py --steps 30 80
    python benchmarks/bench_search_limits.py --cogging --first 640 --n 6
"""
from __future__ import annotations

import argparse
import json
import math
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

from bench_args import positive_int  # the scripts' folder is on sys.path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]

import numpy as np  # noqa: E402

TWO_PI = 2.0 * math.pi
#: check times of the omega_dot bar (frames, inside the records' staircases)
CHECKS = np.arange(150, 1950, 60)


def one_staircase(n: int) -> dict:
    """The search on a true staircase of n steps of 1 Hz (this process's CPU and peak RSS)."""
    from twin.drives import DriveSpec, rotor_mu_req
    from measurement.kinematics.staircase_search import FoundStaircaseInput
    fps = 3000.0
    spec = DriveSpec(kind="staircase_pi", omega0=-TWO_PI * 9, omega_end=-TWO_PI * (9.3 + n),
                     t0=0.03, te=0.5, rounding="lead", tau_motor=0.005, zeta=0.8,
                     omega_n=20.0, setpoint_weight=0.8)
    t = np.arange(int(0.68 * fps)) / fps
    theta = 1.0 + rotor_mu_req(spec, t)["theta"]
    theta += 1e-4 * np.random.default_rng(n).standard_normal(t.size)
    start = time.process_time()
    fit = FoundStaircaseInput().fit(t, theta, 1e-4)
    return {"steps": n, "cpu_s": time.process_time() - start,
            "peak_gb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6,
            "accepted": fit.accepted, "found": fit.params.get("staircase_steps"),
            "why": fit.why[:100]}


def cogging(first: int, n: int, amp: float, order: int) -> None:
    from abu_model.loop_response import Setpoints
    from controller.reference import Staircase
    from measurement.kinematics.estimators import savgol_kinematics
    from measurement.kinematics.staircase_search import FoundStaircaseInput
    from measurement.kinematics.unknown_loop import UnknownLoopInput
    from test_staircase_search import FPS, SIGMA, _record

    def held(fit_or_kin, alpha) -> float:
        e = np.abs(fit_or_kin.omega_dot[CHECKS] - alpha[CHECKS])
        bias = getattr(fit_or_kin, "bias_omega_dot", None)
        bar = 1.96 * fit_or_kin.sigma_omega_dot[CHECKS] + (0 if bias is None else bias[CHECKS])
        return float(np.mean(e <= bar))

    print(f"ripple {amp:g} rad/s^2 at {order} per turn, noise {SIGMA:g} rad, {FPS:g} frames/s")
    for seed in range(first, first + n):
        t, th, alpha, spec = _record(seed, ("lead", "nearest", "trail")[seed % 3])
        omega = np.gradient(th, t)
        th = th - amp * np.sin(order * th) / (order * omega) ** 2   # angle of the ripple
        alpha = alpha + amp * np.sin(order * th)
        stair = Staircase(spec.omega0, spec.omega_end, spec.t0, spec.te, rounding=spec.rounding)
        stated = UnknownLoopInput(setpoints=Setpoints(stair.step_times, stair.levels),
                                  sample_time_s=1.0 / FPS).fit(t, th, SIGMA)
        found = FoundStaircaseInput().fit(t, th, SIGMA)
        sg = savgol_kinematics(t, th, window_s=0.042, polyorder=9, sigma_theta=SIGMA)
        cells = [f"seed {seed}: omega {np.min(np.abs(omega)):.0f}-{np.max(np.abs(omega)):.0f}"
                 " rad/s"]
        for name, fit in (("stated", stated), ("found", found)):
            cells.append(f"{name} " + (f"accepted, bar holds {held(fit, alpha):.0%}"
                                       if fit.accepted else "refused"))
        cells.append(f"Savitzky-Golay bar holds {held(sg, alpha):.0%}")
        print("; ".join(cells))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=positive_int, nargs="+", default=None,
                    help="step counts of the staircases searched (each in its own process)")
    ap.add_argument("--cogging", action="store_true", help="the ripple rows instead")
    ap.add_argument("--first", type=int, default=640)
    ap.add_argument("--n", type=positive_int, default=6)
    ap.add_argument("--amp", type=float, default=10.0, help="ripple amplitude [rad/s^2]")
    ap.add_argument("--order", type=positive_int, default=6, help="ripple periods per turn")
    ap.add_argument("--one", type=int, default=None, help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.one is not None:
        print(json.dumps(one_staircase(a.one)))
        return 0
    if a.cogging:
        cogging(a.first, a.n, a.amp, a.order)
        return 0
    for n in a.steps or [30, 80]:
        out = subprocess.run([sys.executable, __file__, "--one", str(n)], capture_output=True,
                             text=True, check=True).stdout.strip().splitlines()[-1]
        r = json.loads(out)
        print(f"{r['steps']} steps: CPU {r['cpu_s']:.1f} s, peak {r['peak_gb']:.2f} GB, "
              f"accepted {r['accepted']}, steps found {r['found']}"
              + ("" if r["accepted"] else f" ({r['why']})"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
