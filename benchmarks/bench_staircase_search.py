"""The report's staircase found from the record (``abu measure --kinematics drive-model
--find-staircase``, ``measurement/kinematics/staircase_search.py``) on a broad family of
staircase drives at the tracked-angle level (no rendering: many records in minutes), against
the same fit with the true staircase stated (the peer, timed in the same process).

Each record is drawn from its seed (``_draw``): the harsh twin's own digital PI drive
(``twin.drives.rotor_mu_req``: its controller and rotor integration, independent of the
closed-form loop response the fit uses) following one of the report's staircases:

* start speed 4-20 Hz either way, 4-16 steps of 1 Hz, away from zero or towards it; start
  0-0.1 s, duration te 0.2-0.7 s, the whole staircase in the record (0.08-0.25 s after it);
* any rounding (lead, nearest, trail);
* loop: zeta 0.5-1.0, omega_n 8-40 rad/s, a torque lag up to 80 % of the stable limit
  (at most 30 ms), setpoint weight 0.5-1, a 2-20 ms setpoint filter in 60 %;
* the controller at the frame rate (half the records: 2000-6000 frames/s), at 10 kHz filmed
  at 2000, 2500 or 5000 frames/s (a quarter), or at 30-45 kHz, ten samples a frame, next to
  continuous (a quarter). The twin samples its controller on the frame times' grid, so a
  controller rate that is not a multiple of the frame rate is not drawn;
* tracking noise 0.5-3e-4 rad; a fixed lens pattern of 0-8e-4 rad in harmonics 1 and 2 of
  the angle.

Printed per family slice: how many fits are accepted, how many of those found the drive's
staircase (rounding, step count, every step within 3 frames but for a common shift; te within
0.3 %), the 95 % bar's coverage of the true
omega_dot at check times inside the staircase, omega_dot's RMS error against the stated
staircase's and Savitzky-Golay's (the default), and the CPU time per record (process time,
one BLAS thread) of the search and of the stated-staircase fit, with their median ratio;
the records accepted only when tried again after a refusal near the limit, with the count's
change.

Run::

    nice python benchmarks/bench_staircase_search.py --first 0 --n 24 --jobs 2

and, against the search of another commit (alternated pairs of fresh processes, CPU of the
search alone)::

    git worktree add /tmp/before COMMIT
    python benchmarks/bench_staircase_search.py --first 0 --n 6 --against /tmp/before
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import time
from multiprocessing import Pool
from pathlib import Path

from bench_args import positive_int  # the scripts' folder is on sys.path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]
# --code DIR: the search of another checkout (the timing pairs of --against run this file so)
CODE = Path(sys.argv[sys.argv.index("--code") + 1]) if "--code" in sys.argv else ROOT
sys.path[:0] = [str(CODE)]

import numpy as np  # noqa: E402

TWO_PI = 2.0 * math.pi
ROUNDINGS = ("lead", "nearest", "trail")
#: "The drive's staircase found": its rounding and step count, and every step within this
#: many frames of the drive's, but for a shift common to all (the record's time offset to
#: the staircase, fitted apart). te alone is loose with few steps: it trades off with the span
STEP_FRAMES = 3.0
#: A bar "holds" the true omega_dot within this [rad/s^2] as well: before the first step the
#: model's omega_dot and its bar are exactly 0, the twin's omega_dot is 0 or ~1e-13 (its
#: round-off with several controller samples a frame), which is no miss
ALPHA_TOL = 1e-6


def _draw(seed: int):
    """(t, theta measured, true omega_dot, DriveSpec, sigma, controller samples per frame)."""
    from twin.drives import DriveSpec, rotor_mu_req
    rng = np.random.default_rng([seed, 4711])
    u = rng.uniform
    clock = u()
    if clock < 0.5:      # the controller at the frame rate (the rendered twin's)
        fps, per_frame = float(rng.choice([2000.0, 3000.0, 4500.0, 6000.0])), 1
    elif clock < 0.75:   # a 10 kHz controller filmed at a divisor of its rate
        fps = float(rng.choice([2000.0, 2500.0, 5000.0]))
        per_frame = int(round(10000.0 / fps))
    else:                # a controller at 30-45 kHz: next to continuous
        fps, per_frame = float(rng.choice([3000.0, 4500.0])), 10
    sign = -1.0 if u() < 0.7 else 1.0
    steps = u(4.0, 16.0)
    f0 = u(4.0, 20.0)
    towards_zero = u() < 0.3 and f0 - steps > 1.0
    f_end = f0 - steps if towards_zero else f0 + steps
    zeta, omega_n = u(0.5, 1.0), u(8.0, 40.0)
    tau = min(0.03, u(0.0, 0.8) * 2.0 * zeta / omega_n)
    t0, te = u(0.0, 0.1), u(0.2, 0.7)
    spec = DriveSpec(kind="staircase_pi", omega0=sign * TWO_PI * f0,
                     omega_end=sign * TWO_PI * f_end, t0=t0, te=te,
                     rounding=ROUNDINGS[int(rng.integers(3))], tau_motor=tau, zeta=zeta,
                     omega_n=omega_n, setpoint_weight=u(0.5, 1.0),
                     setpoint_tau=0.0 if u() < 0.4 else u(0.002, 0.02))
    n_frames = int((t0 + te + u(0.08, 0.25)) * fps)
    fine = np.arange(n_frames * per_frame) / (fps * per_frame)
    r = rotor_mu_req(spec, fine)
    t = fine[::per_frame]
    truth = r["theta"][::per_frame]
    sigma = u(0.5e-4, 3e-4)
    lens = u(0.0, 8e-4) * np.cos(truth + u(0, TWO_PI)) \
        + u(0.0, 3e-4) * np.cos(2 * truth + u(0, TWO_PI))
    theta = 1.0 + truth + lens + sigma * rng.standard_normal(t.size)
    return t, theta, r["alpha"][::per_frame], spec, sigma, per_frame


def _one(seed: int) -> dict:
    from controller.reference import Staircase
    from abu_model.loop_response import Setpoints
    from measurement.kinematics.estimators import savgol_kinematics
    from measurement.kinematics.staircase_guess import ROUNDING_OFFSETS, SineStaircase
    from measurement.kinematics.staircase_search import FoundStaircaseInput
    from measurement.kinematics.unknown_loop import FIND, UnknownLoopInput
    t, th, alpha, spec, sigma, per_frame = _draw(seed)
    start = time.process_time()
    fit = FoundStaircaseInput().fit(t, th, sigma)
    cpu = time.process_time() - start
    stair = Staircase(spec.omega0, spec.omega_end, spec.t0, spec.te, rounding=spec.rounding)
    start = time.process_time()
    stated = UnknownLoopInput(setpoints=Setpoints(stair.step_times, stair.levels),
                              sample_time_s=FIND).fit(t, th, sigma)
    cpu_stated = time.process_time() - start
    sg = savgol_kinematics(t, th, window_s=0.042, polyorder=9, sigma_theta=sigma)
    dt = float(t[1] - t[0])
    checks = np.arange(int((spec.t0 + 0.02) / dt), min(int((spec.t0 + spec.te) / dt),
                                                       t.size - 1), 7)
    span = abs(spec.omega_end - spec.omega0) / spec.step
    p = fit.params
    right = bool(fit.accepted
                 and p.get("staircase_rounding_offset") == ROUNDING_OFFSETS[spec.rounding]
                 and p.get("staircase_steps") == math.floor(span))
    te_rel = abs(p.get("staircase_te_s", math.nan) / spec.te - 1.0)
    if right:   # every step within STEP_FRAMES frames of the drive's
        found = SineStaircase(p["staircase_t0_s"], p["staircase_rounding_offset"],
                              int(p["staircase_steps"]), 0.0, 1.0, spec.step).setpoints(
            p["staircase_te_s"], p["staircase_span_steps"]).step_times
        d = np.subtract(found, stair.step_times)
        right = float(np.max(np.abs(d - np.median(d)))) <= STEP_FRAMES * dt
    row = dict(seed=seed, accepted=bool(fit.accepted), right=right, te_rel=te_rel, cpu=cpu,
               count_change=p.get("staircase_count_change"),
               cpu_stated=cpu_stated, stated_accepted=bool(stated.accepted),
               why=fit.why[:120], per_frame=per_frame, fps=1.0 / dt,
               te=spec.te, steps=math.floor(span), rounding=spec.rounding,
               err_sg=float(np.sqrt(np.mean((sg.omega_dot[checks] - alpha[checks]) ** 2))))
    if fit.accepted:
        e = fit.omega_dot[checks] - alpha[checks]
        row.update(err=float(np.sqrt(np.mean(e**2))),
                   inside=float(np.mean(np.abs(e) <= 1.96 * fit.sigma_omega_dot[checks]
                                        + ALPHA_TOL)))
    if stated.accepted:
        e = stated.omega_dot[checks] - alpha[checks]
        row.update(err_stated=float(np.sqrt(np.mean(e**2))), inside_stated=float(
            np.mean(np.abs(e) <= 1.96 * stated.sigma_omega_dot[checks] + ALPHA_TOL)))
    return row


def _report(rows: list[dict], label: str) -> None:
    n = len(rows)
    acc = [r for r in rows if r["accepted"]]
    both = [r for r in acc if "err_stated" in r]
    med = (lambda v: float(np.median(v)) if len(v) else math.nan)
    cpu = np.array([r["cpu"] for r in rows])
    ratio = [r["cpu"] / r["cpu_stated"] for r in rows if r["cpu_stated"] > 0]
    print(f"\n{label}: {n} records")
    print(f"  accepted {len(acc)} of {n}; the drive's staircase found (rounding, step count, "
          f"each step within {STEP_FRAMES:g} frames but for a common shift) in {sum(r['right'] for r in acc)} of them, "
          f"te within 0.3 % in {sum(r['te_rel'] < 0.003 for r in acc)}; the stated "
          f"staircase's fit accepted in {sum(r['stated_accepted'] for r in rows)}")
    print(f"  95 % bar holds the true omega_dot at {med([r['inside'] for r in acc]):.1%} of "
          f"the check times (median over the accepted; lowest "
          f"{min([r['inside'] for r in acc], default=math.nan):.1%}); with the staircase "
          f"stated {med([r['inside_stated'] for r in both]):.1%} (median over both)")
    print(f"  omega_dot RMS error, median over records accepted by both: found "
          f"{med([r['err'] for r in both]):.3g}, stated {med([r['err_stated'] for r in both]):.3g}"
          f", Savitzky-Golay {med([r['err_sg'] for r in both]):.3g} rad/s^2")
    if n:
        print(f"  CPU a record: median {np.median(cpu):.1f} s (10-90 %: "
              f"{np.percentile(cpu, 10):.1f}-{np.percentile(cpu, 90):.1f} s); "
              f"against the stated staircase's fit: median ratio {med(ratio):.1f}x")
    again = [f"{r['seed']} (" + ("the same count" if r["count_change"] == 0
                                 else f"{r['count_change']:+.0f} step") + ")"
             for r in acc if r["count_change"] is not None]
    print(f"  accepted when tried again (refused near the limit first): {len(again)}"
          + (f": {', '.join(again)}" if again else ""))
    for per in sorted({r["per_frame"] for r in rows}):
        sub = [r for r in rows if r["per_frame"] == per]
        sub_acc = [r for r in sub if r["accepted"]]
        clock = "at the frame rate" if per == 1 else f"{per} samples a frame"
        print(f"  controller {clock}: accepted {len(sub_acc)} of {len(sub)}; 95 % bar "
              f"coverage (median) found {med([r['inside'] for r in sub_acc]):.1%}, stated "
              f"{med([r['inside_stated'] for r in sub if 'inside_stated' in r]):.1%}")
    for r in rows:
        if not r["right"]:
            print(f"    seed {r['seed']}: {'accepted' if r['accepted'] else 'refused'}, "
                  f"{r['fps']:.0f}/s x{r['per_frame']}, {r['steps']} steps {r['rounding']}, "
                  f"te {r['te']:.3f} s: {r['why']}")


def _search_cpu(seeds: list[int]) -> float:
    """CPU time [s] of the search alone over these seeds' records (one process)."""
    from measurement.kinematics.staircase_search import FoundStaircaseInput
    total = 0.0
    for seed in seeds:
        t, th, _, _, sigma, _ = _draw(seed)
        start = time.process_time()
        FoundStaircaseInput().fit(t, th, sigma)
        total += time.process_time() - start
    return total


def _pairs(other: str, seeds: list[int], pairs: int) -> None:
    """The search of this checkout against that of ``other``, in fresh processes taken in
    turn, ``pairs`` times: each side's CPU over the seeds and the median ratio."""
    import subprocess
    cmd = [sys.executable, __file__, "--first", str(seeds[0]), "--n", str(len(seeds)),
           "--cpu-only", "--code"]
    ratios = []
    for _ in range(pairs):
        cpu = [float(subprocess.run(cmd + [code], capture_output=True, text=True, check=True)
                     .stdout.split()[-1]) for code in (other, str(ROOT))]
        ratios.append(cpu[0] / cpu[1])
        print(f"  {other}: {cpu[0]:.1f} s, this checkout: {cpu[1]:.1f} s", flush=True)
    print(f"seeds {seeds[0]}-{seeds[-1]}, {pairs} pairs: this checkout's search takes "
          f"{float(np.median(ratios)):.2f}x less CPU (median ratio)")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--first", type=int, default=0, help="first seed")
    ap.add_argument("--n", type=int, default=24, help="records")
    ap.add_argument("--jobs", type=int, default=1, help="worker processes")
    ap.add_argument("--against", default=None, metavar="DIR",
                    help="time the search against that of another checkout (e.g. 'git "
                         "worktree add DIR COMMIT'), in alternated pairs; nothing else is run")
    ap.add_argument("--pairs", type=positive_int, default=3, help="pairs with --against")
    ap.add_argument("--code", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--cpu-only", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    seeds = list(range(args.first, args.first + args.n))
    if args.cpu_only:
        print(f"{_search_cpu(seeds):.3f}")
        return 0
    if args.against:
        _pairs(args.against, seeds, args.pairs)
        return 0
    if args.jobs > 1:
        with Pool(args.jobs) as pool:
            rows = pool.map(_one, seeds, chunksize=1)
    else:
        rows = [_one(s) for s in seeds]
    for r in rows:
        print(f"seed {r['seed']}: accepted {r['accepted']}, right {r['right']}, "
              f"cpu {r['cpu']:.1f} s (stated {r['cpu_stated']:.1f} s)", flush=True)
    _report(rows, f"seeds {seeds[0]}-{seeds[-1]}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
