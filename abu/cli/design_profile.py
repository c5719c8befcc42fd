"""``abu design --drive tracking.json``: the prescribed profile for a prior range of mu.

Dispatched from :func:`abu.cli.plan.cmd_design` when the drive is of model ``tracking``
(:mod:`harness.planning.design_profile`). Writes ``profile.json`` (for ``abu render``,
``abu measure --kinematics drive-model``) and ``design.json`` into ``--out``.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

from abu_model.errors import ParameterError

from abu.cli.common import camera_fps, finite, in_range, integer_range, positive

HZ = 2.0 * math.pi
#: the profile's speed cap without --speed-max-hz [Hz]: the benchmark's (bench_profile_drive.py
#: measured 30 + 30 designed runs with it; the staircase design's default, 50 Hz, is untested
#: for the tracker at the profile's sustained speeds)
SPEED_MAX_HZ = 40.0
#: staircase-only options of ``abu design``, refused with a tracking drive (the profile's
#: width predictor assumes the drive-model kinematics and its own calibrated noise)
STAIRCASE_ONLY = ("--step-hz", "--slip-window-s", "--objective", "--fmu-dir", "--noise-from",
                  "--kinematics", "--camera", "--cd-circle")


def profile_spec(args: argparse.Namespace, drive):
    """The design's settings from the options (each bad one named)."""
    from abu_model.params import BallParams
    from harness.planning.design_profile import ProfileDesignSpec

    lo, hi = (finite("--mu-range", v) for v in args.mu_range)
    camera_fps("--fps", args.fps)
    integer_range("--frames", args.frames, 100, 100_000, "frames per record")
    from abu.cli.common import given
    speed_max = args.speed_max_hz if given(args, "--speed-max-hz") else SPEED_MAX_HZ
    in_range("--speed-max-hz", speed_max, 1.0, 200.0, "Hz",
             "CD drives spin at most about 200 Hz")
    try:
        return ProfileDesignSpec(
            lo, hi, drive, ball=BallParams(l=positive("--l", args.l, "m"),
                                           d=positive("--d", args.d, "m")),
            fps=args.fps, n_frames=args.frames,
            speed_max=speed_max * HZ,
            speed_min=positive("--speed-min-hz", args.speed_min_hz, "Hz") * HZ,
            edge_s=positive("--edge-s", args.edge_s, "s"),
            direction=-1 if args.direction == "cw" else 1)
    except ParameterError as exc:
        if exc.parameter in ("--mu-range", "--speed-min-hz", "--drive"):
            raise
        raise ParameterError("--mu-range", (lo, hi), exc.expected) from None


def describe(design) -> str:
    """The design in a few lines (stdout)."""
    s, ph = design.spec, design.phases
    lines = [f"profile design for mu in [{s.mu_lo:.4g}, {s.mu_hi:.4g}] with the tracking drive "
             f"(bandwidth {s.drive.bandwidth:.4g} rad/s, tau_motor {s.drive.tau_motor:.3g} s):",
             f"  mu_req swept from {ph['q0']:.4g} to {ph['q1']:.4g} at {design.rate:.4g} /s "
             f"over [{ph['t_sweep_start_s']:.3f}, {ph['t_sweep_end_s']:.3f}] s; speed "
             f"{ph['speed_start_rad_s'] / HZ:.3g} Hz -> {ph['speed_end_rad_s'] / HZ:.3g} Hz "
             f"(cap {s.speed_cap() / HZ:.3g} Hz: --speed-max-hz and the ball's blur); "
             f"{len(design.profile.times)} knots",
             f"  {'mu [-]':>10} {'t_slip [s]':>10} {'speed [Hz]':>10} {'width [%]':>9} "
             f"{'upper [%]':>9}"]
    upper = design.upper()
    for k in range(0, design.mus.size, 2):
        lines.append(f"  {design.mus[k]:>10.4g} {design.t_slip[k]:>10.4f} "
                     f"{design.speed[k] / HZ:>10.3g} {100 * design.width[k]:>9.1f} "
                     f"{100 * upper[k]:>9.1f}")
    lines.append(f"  predicted relative width: median {100 * float(np.median(design.width)):.1f} %, "
                 f"worst {100 * float(design.width.max()):.1f} % (mu_d = 0.8 mu); upper "
                 f"{100 * float(upper.max()):.1f} % (mu_d = mu: the slowest onset)")
    lines.append("  check it: abu simulate --motion profile --drive DRIVE --profile profile.json "
                 "--mu MU")
    lines.append("  abu render --drive DRIVE --profile profile.json --mu MU --out REC")
    lines.append("  abu measure REC/frames.tif --kinematics drive-model --drive DRIVE "
                 "--profile profile.json --out M")
    return "\n".join(lines)


def cmd_design_profile(args: argparse.Namespace, drive) -> int:
    """``abu design`` with a tracking drive."""
    from abu.cli.common import refuse_given
    from controller.profile import dumps_profile
    from harness.planning.design_profile import design_profile
    from harness.experiments.results_io import to_jsonable

    def _dumps(obj) -> str:
        return json.dumps(to_jsonable(obj), indent=2, allow_nan=False) + "\n"

    refuse_given(args, STAIRCASE_ONLY, "with a tracking --drive (they set up a staircase or "
                 "its width prediction; the profile's assumes the drive-model kinematics)")
    design = design_profile(profile_spec(args, drive))
    payload = design.summary()
    if args.out:
        from abu.cli.output_tx import output_folder
        with output_folder(args.out, overwrite=args.overwrite) as tmp:
            (tmp / "profile.json").write_text(dumps_profile(design.profile), encoding="utf-8")
            (tmp / "design.json").write_text(_dumps(payload), encoding="utf-8")
    if args.json:
        sys.stdout.write(_dumps(payload))
    else:
        print(describe(design))
        if args.out:
            print(f"wrote {Path(args.out) / 'profile.json'} and {Path(args.out) / 'design.json'}")
    return 0
