"""Checks of the measurement commands' options (``track``, ``measure``, ``render``).

Each names the option as typed, the value, the limit and why; all run before reading,
tracking, simulating or rendering anything (issue 11).
"""
from __future__ import annotations

import argparse

from abu_model.errors import ParameterError
from abu.cli.common import camera_fps, count_limit, in_range, integer_range, positive

#: Option limits (why: in the messages).
MAX_MC_DRAWS = 100_000
MAX_POLY_DEGREE = 30
MAX_RECORD_S = 100.0
#: Ranges of the render options (option, low, high, unit, why); checked when present.
RENDER_RANGES = (
    ("--mu", 0.0, 2.0, "", "dry friction coefficients are below about 1"),
    ("--omega0-hz", -1000.0, 1000.0, "Hz", "CD drives spin at most about 200 Hz"),
    ("--omega-end-hz", -1000.0, 1000.0, "Hz", "CD drives spin at most about 200 Hz"),
    ("--t0", -100.0, 100.0, "s", "start of the staircase; the report's record lasts 0.68 s"),
    ("--te", 1e-6, 100.0, "s", "duration of the staircase; the report's is 0.5 s"),
    ("--beta0", -1000.0, 1000.0, "rad", "an initial angle"),
    ("--zeta", 1e-6, 1000.0, "", "a damping ratio"),
    ("--omega-n", 1e-6, 1e4, "rad/s", "the drive's natural frequency; the twin's is 12"),
    ("--tau-motor", 0.0, 1.0, "s", "a motor answers in milliseconds"),
    ("--noise", 0.0, 255.0, "grey levels", "8-bit frames"),
    ("--gradient", -255.0, 255.0, "grey levels/px", "8-bit frames"),
    ("--ball-shift-px", -100.0, 100.0, "px", "an offset of the ball's apparent centre"),
    ("--exposure-fraction", 0.0, 1.0, "", "exposure / frame interval"),
    ("--pixel-size", 1e-7, 1e-2, "m/px", "the camera's pixel size on the ABU"),
    ("--seed", 0, 2**63 - 1, "", "a noise seed (non-negative)"),
)


def check_analysis_options(args: argparse.Namespace) -> None:
    """``abu measure``'s analysis options."""
    integer_range("--seed", args.seed, 0, 2**63 - 1, "a Monte Carlo seed (non-negative)")
    integer_range("--mc-draws", args.mc_draws, 0, MAX_MC_DRAWS,
                  "each draw reruns the analysis, about 50 ms")
    integer_range("--poly-degree", args.poly_degree, 1, MAX_POLY_DEGREE,
                  "the report estimator's global polynomial; higher degrees are ill-conditioned")
    if args.trim_s is not None:
        positive("--trim-s", args.trim_s, "s", allow_zero=True)
    if args.sg_window_s is not None:
        in_range("--sg-window-s", args.sg_window_s, 1e-6, 1.0, "s",
                 "the record lasts well under a second")
    if args.k_sigma is not None:
        in_range("--k-sigma", args.k_sigma, 0.1, 100.0, "", "a multiple of the error bar")


def check_tracking_options(args: argparse.Namespace) -> None:
    """Options shared by ``abu track`` and ``abu measure``."""
    from measurement.imaging.tracking import METHODS
    if args.method not in METHODS:
        raise ParameterError("--method", args.method, f"one of {', '.join(METHODS)}")
    positive("--fps", args.fps, "frames/s", allow_none=True)
    if args.fps is not None:
        camera_fps("--fps", args.fps)
    if args.window is not None:   # None: sized from the markers (window_size)
        integer_range("--window", args.window, 8, 4096, "the square tracking window around a "
                      "marker [px]")


def check_render_options(args: argparse.Namespace) -> None:
    """Limits of a rendered recording, before simulating and rendering it."""
    from measurement.imaging.recording_checks import MAX_FRAMES, MAX_PIXELS
    integer_range("--frames", args.frames, 1, MAX_FRAMES,
                  "frames held in memory; the report's camera stores 3072 per run")
    camera_fps("--fps", args.fps)
    size = getattr(args, "size", 256)
    if isinstance(size, int):
        integer_range("--size", size, 16, 4096, "frame width and height [px]")
        count_limit("--frames", args.frames, args.frames * size * size, MAX_PIXELS,
                    "pixels", "the recording is rendered in memory")
    count_limit("--frames", args.frames, args.frames / args.fps, MAX_RECORD_S, "s of recording",
                "each frame is simulated and rendered; the report's record lasts 0.68 s")
    for option, low, high, unit, why in RENDER_RANGES:
        value = getattr(args, option[2:].replace("-", "_"), None)
        if value is not None and not isinstance(value, str):
            if isinstance(value, int) and not isinstance(value, bool) and option == "--seed":
                integer_range(option, value, int(low), int(high), why)
            else:
                in_range(option, value, low, high, unit, why)
    if getattr(args, "mu", 1.0) is not None and getattr(args, "mu", 1.0) <= 0:
        raise ParameterError("--mu", args.mu, "a friction coefficient > 0")
