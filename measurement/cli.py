"""Measurement commands of the ``abu`` command line: ``track``, ``measure``, ``measure-summary``,
``render`` (:mod:`measurement.cli_render`), and ``calibrate-camera``, ``measure --camera``
(:mod:`measurement.cli_camera`); the printed text of the summaries is
:mod:`measurement.summary_text`.

``harness/cli.py`` builds the main parser and calls :func:`register`; every subcommand sets
``func`` (``args -> exit status``). Errors derived from :class:`abu_model.errors.AbuError` are
printed by the main program, which exits with status 2. :func:`main` is a stand-alone entry
point with the same behaviour (used by the tests and ``python -m measurement.cli``).

Outputs are computed completely before anything is written, and every file is written
atomically, so a failing command leaves no half-written file behind.
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Sequence

import numpy as np

from abu_model.atomic_io import atomic_write_text
from abu_model.errors import AbuError, ParameterError
from harness.cli_common import (MAX_BINS, AbuArgumentParser, add_overwrite, in_range,
                                integer_range, log as _log, option_error, run_command)
from harness.output_tx import check_not_inside, output_folder

from .cli_checks import check_analysis_options, check_tracking_options
from .cli_render import cmd_render
from .input_checks import check_motion_and_roles, check_sampling
from .json_text import dumps, json_ready  # noqa: F401  (json_ready: public name of this module)
from .summary_text import describe_combined, describe_measurement

DEFAULT_FPS = 4500.0
#: ``kind`` and ``format_version`` of the summary.json of ``abu measure`` (readers check them).
SUMMARY_KIND = "abu-measure-summary"
SUMMARY_VERSION = 1
COMBINED_KIND = "abu-measure-summary-combined"
DEFAULT_L = 1.15e-2
DEFAULT_D = 3.0e-3


# ------------------------------------------------------------------------------ helpers

def _positive(name: str, value: float | None, unit: str) -> float | None:
    if value is None:
        return None
    if not (math.isfinite(value) and value > 0):
        raise ParameterError(name, value, f"a finite number > 0 {unit}".rstrip())
    return float(value)


def format_table_csv(table: dict[str, np.ndarray]) -> str:
    """CSV text of a table of equal-length columns (names carry the units)."""
    from .tracks_io import table_csv_text
    names = list(table)
    # Plain CSV (no comment line): units are in the column names (_s, _rad, _rad_s, _rad_s2);
    # mu_* and running_max_* are dimensionless; trusted 0/1; lost bit mask 1 center 2 cd 4 ball;
    # non-finite values are empty cells.
    return table_csv_text(names, [np.asarray(table[n]) for n in names])


# ------------------------------------------------------------------------------ tracking

def _track_frames(args: argparse.Namespace, fps: float, check=None) -> dict:
    """Read the recording, find or parse the seeds, track; returns the pieces for writing.

    ``check(n_frames)`` is called after reading, before tracking (input checks).
    """
    from .frames_io import read_recording
    from .markers import find_markers, format_seeds, parse_seeds
    from .reflections import track_markers
    from . import tracks_io

    rec = read_recording(args.input)
    frames = rec.frames
    if check is not None:
        check(len(rec))
    if args.seeds is not None:
        try:
            seeds = parse_seeds(args.seeds)
        except AbuError as exc:
            raise AbuError(f"--seeds: {exc}") from None
        roles_note = "given by --seeds"
    else:
        seeds, roles = find_markers(np.asarray(frames[0]), dark=args.dark_markers,
                                    ball_reflections=args.ball_reflections)
        roles_note = "found in frame 0"
        _log(args, "markers found in frame 0 (x, y px): " + ", ".join(
            f"{role} ({sx:.2f}, {sy:.2f})" for role, (sx, sy) in zip(roles, seeds)))
        _log(args, f"  reuse or correct with --seeds '{format_seeds(seeds)}'")
    h, w = frames.shape[1:]
    for i, (sx, sy) in enumerate(seeds):
        if not (0 <= sx <= w - 1 and 0 <= sy <= h - 1):
            raise ParameterError("--seeds", format_seeds(seeds),
                                 f"positions inside the {w}x{h} px frame (position {i + 1} "
                                 "is outside)")
    tracks = track_markers(frames, seeds, method=args.method, window=args.window,
                           dark=args.dark_markers, progress=args.progress,
                           ball_reflections=args.ball_reflections, ball_method=args.ball_method)
    time = np.arange(tracks.n_frames) / fps
    lost = np.asarray(tracks.lost, dtype=bool)
    try:
        x = tracks_io.fill_lost(time, tracks.x, lost)
        y = tracks_io.fill_lost(time, tracks.y, lost)
    except tracks_io.LostMarkerError as exc:
        # Name the frame as the recording knows it (file name for a folder of frames).
        reasons = tracks.lost_summary()
        hint = ("; if the ball shows two reflections, use --ball-reflections 2"
                if args.ball_reflections == 1 and tracks.lost[:, 2].any() else "")
        raise tracks_io.LostMarkerError(f"{rec.source}: {exc}; lost reasons: {reasons}"
                                        f"{hint}") from None
    return {"time": time, "x": x, "y": y, "lost": lost, "seeds": seeds, "source": rec.source,
            "seeds_note": roles_note, "method": tracks.method, "window": tracks.window,
            "lost_reasons": tracks.lost_summary(), "frame_size": (w, h)}


def _tracking_info(tr: dict, fps: float) -> dict:
    from .markers import format_seeds
    return {"source": tr["source"], "seeds_px": format_seeds(tr["seeds"]),
            "seeds": tr["seeds_note"], "roles": ["center", "cd", "ball"],
            "method": tr["method"], "window_px": tr["window"], "fps_hz": fps,
            "frames": int(tr["time"].size),
            "lost_frames": {name: int(tr["lost"][:, j].sum())
                            for j, name in enumerate(["center", "cd", "ball"])},
            "lost_reasons": tr["lost_reasons"]}


def cmd_track(args: argparse.Namespace) -> int:
    """``abu track INPUT --out DIR``: marker tracks only (tracks.csv, tracking.json)."""
    check_tracking_options(args)
    from . import tracks_io
    fps = _positive("--fps", args.fps, "frames/s") or DEFAULT_FPS
    out = Path(args.out)
    check_not_inside(out, [args.input])
    with output_folder(out, overwrite=args.overwrite) as tmp:
        tr = _track_frames(args, fps)
        theta, beta = tracks_io.angles_from_pixels(tr["x"], tr["y"])
        csv_text = tracks_io.format_tracks_csv(tr["time"], theta, beta, tr["x"], tr["y"],
                                               tr["lost"])
        info = _tracking_info(tr, fps)
        atomic_write_text(tmp / "tracks.csv", csv_text)
        atomic_write_text(tmp / "tracking.json", dumps(info))
    _log(args, f"wrote {out / 'tracks.csv'} ({info['frames']} frames, lost "
               f"{info['lost_frames']})")
    return 0


# ------------------------------------------------------------------------------ measure

def _analysis_options(args: argparse.Namespace):
    from .analysis import AnalysisOptions
    from .inference import InferenceOptions
    from .interval import IntervalOptions
    check_analysis_options(args)
    return AnalysisOptions(
        estimator=args.estimator, sg_window_s=_positive("--sg-window-s", args.sg_window_s, "s"),
        poly_degree=args.poly_degree, trim_s=args.trim_s, harmonic=not args.no_harmonic,
        harmonic_phase=args.harmonic_phase,
        interval=IntervalOptions(k_sigma=_positive("--k-sigma", args.k_sigma, ""),
                                 lower=args.lower),
        mc_draws=args.mc_draws, seed=args.seed,
        inference=InferenceOptions(confidence=in_range(
            "--confidence", args.confidence, 0.5, 0.9999, "", "a probability, e.g. 0.95")))


def cmd_measure(args: argparse.Namespace) -> int:
    """``abu measure INPUT --out DIR``: track (or read tracks) and analyse."""
    check_tracking_options(args)
    if getattr(args, "drive", None):  # a bad drive.json fails before the tracking
        from controller.drive import load_drive
        load_drive(args.drive)
    camera = None
    if getattr(args, "camera", None):  # so does a bad camera file (read once, used later)
        from .camera import read_camera
        camera = read_camera(args.camera)
    l = in_range("--l", _positive("--l", args.l, "m"), 1e-4, 1.0, "m",
                 "radius of the ball centre's path; a CD drive's is 1.15e-2 m")
    d = in_range("--d", _positive("--d", args.d, "m"), 1e-5, 0.1, "m",
                 "ball diameter; the report's is 3e-3 m")
    fps_opt = _positive("--fps", args.fps, "frames/s")
    options = _analysis_options(args)
    out = Path(args.out)
    check_not_inside(out, [args.input])
    with output_folder(out, overwrite=args.overwrite) as tmp:
        summary = _measure(args, l, d, fps_opt, options, tmp, camera)
    if args.json:
        sys.stdout.write(dumps(summary))
    else:
        print(describe_measurement(summary))
    return 0


def _check_sampling(args: argparse.Namespace, time: np.ndarray, source: str, options) -> None:
    check_sampling(time, source, fps_option="--fps", sg_window_s=options.sg_window_s,
                   polyorder=options.sg_polyorder, estimator=options.estimator,
                   trim_s=options.trim_s)


def _measure(args: argparse.Namespace, l: float, d: float, fps_opt: float | None, options,
             out: Path, camera=None) -> dict:
    """Track or read the tracks, analyse, write everything into ``out``; returns the summary.
    ``camera``: the :class:`measurement.camera.Camera` of ``--camera`` (None: no undistortion)."""
    from . import tracks_io
    from .analysis import analyse_tracks

    if args.tracks:
        table_in = tracks_io.read_tracks_csv(args.input)
        time, x, y, lost = table_in.time, table_in.x, table_in.y, table_in.lost
        if fps_opt is not None:
            dt = float(np.median(np.diff(time)))
            if abs(dt * fps_opt - 1.0) > 1e-3:
                raise ParameterError("--fps", fps_opt, f"the frame rate of the tracks file "
                                     f"{args.input} ({1.0 / dt:.6g} frames/s from its time "
                                     "column), or leave --fps out")
        tracking = {"source": str(args.input), "tracks_csv": True}
        _check_sampling(args, time, str(args.input), options)
        x_f = tracks_io.fill_lost(time, x, lost)
        y_f = tracks_io.fill_lost(time, y, lost)
    else:
        fps = fps_opt or DEFAULT_FPS
        tr = _track_frames(args, fps, check=lambda n: _check_sampling(
            args, np.arange(n) / fps, "--fps", options))
        time, x_f, y_f, lost = tr["time"], tr["x"], tr["y"], tr["lost"]
        tracking = _tracking_info(tr, fps)
    check_motion_and_roles(time, x_f, y_f, str(args.input))
    x_a, y_a, camera_info = x_f, y_f, None
    if camera is not None:  # undistort; theta's harmonic prior from the calibration
        from .cli_camera import apply_camera
        x_a, y_a, options, camera_info = apply_camera(
            args.camera, camera, x_f, y_f, None if args.tracks else tr["frame_size"], options)
    table, summary = analyse_tracks(time, x_a, y_a, l=l, d=d, lost=lost, options=options)
    summary = {"kind": SUMMARY_KIND, "format_version": SUMMARY_VERSION, "input": tracking,
               **summary, **({"camera": camera_info} if camera_info else {})}
    if getattr(args, "drive", None):
        from controller.drive import load_drive
        summary["drive"] = load_drive(args.drive).to_dict()
    theta = table["theta_rad"]
    beta = table["beta_rad"]
    tracks_text = tracks_io.format_tracks_csv(time, theta, beta, x_f, y_f, lost)
    table_text = format_table_csv(table)
    summary_text = dumps(summary)
    atomic_write_text(out / "tracks.csv", tracks_text)
    atomic_write_text(out / "kinematics.csv", table_text)
    if not args.no_plots:
        from .plots import plot_analysis  # matplotlib only when plotting
        plot_analysis(table, summary, out)
    atomic_write_text(out / "summary.json", summary_text)
    return summary


# ------------------------------------------------------------------------------ summary of runs

def cmd_measure_summary(args: argparse.Namespace) -> int:
    """``abu measure-summary SUMMARY.json ... --out DIR``: combine several records' intervals."""
    from .multi import combine_summaries, plot_histogram, read_intervals

    out = Path(args.out)
    integer_range("--bins", args.bins, 2, MAX_BINS, "grid points of the drawn histogram; the "
                  "counts are exact at any grid")
    check_not_inside(out, args.summaries)
    intervals = read_intervals(args.summaries)
    with output_folder(out, overwrite=args.overwrite) as tmp:
        result = {"kind": COMBINED_KIND, "format_version": SUMMARY_VERSION,
                  **combine_summaries(intervals, bins=args.bins)}
        text = dumps(result)
        plot_histogram(result, tmp / "histogram.png")
        atomic_write_text(tmp / "measure_summary.json", text)
    if args.json:
        sys.stdout.write(text)
    else:
        print(describe_combined(result))
    return 0


# ------------------------------------------------------------------------------ parser

def _add_tracking_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--fps", type=float, default=None,
                   help=f"frame rate [frames/s] (default {DEFAULT_FPS:g}; with --tracks the "
                        "CSV's time column is used)")
    p.add_argument("--seeds", default=None,
                   help="marker positions in frame 0, 'x,y;x,y;x,y' [px] (x = column, y = row) "
                        "in the order ABU centre; CD marker; ball. Default: found automatically")
    p.add_argument("--dark-markers", action="store_true",
                   help="markers are darker than their surroundings")
    p.add_argument("--method", default="isocontour",
                   help="centre-finding method: isocontour (default), report, moments")
    p.add_argument("--window", type=int, default=30, help="tracking window [px] (default 30)")
    p.add_argument("--ball-reflections", type=int, choices=[1, 2], default=1,
                   help="bright reflections on the ball: 1 (default; one marker at the ball) "
                        "or 2 (the report's two-spot lighting, sec. 5.2)")
    p.add_argument("--ball-method", choices=["outline", "pair"], default="outline",
                   help="with --ball-reflections 2: outline (default; circle fit to the ball's "
                        "silhouette) or pair (the report's way: the mean of the reflections)")
    p.add_argument("--progress", action="store_true", help="progress bar while tracking")
    p.add_argument("--quiet", action="store_true", help="no messages on stderr")


def register(subparsers) -> None:
    """Add ``track``, ``measure``, ``measure-summary`` and ``render`` to ``subparsers``."""
    p = subparsers.add_parser("track", help="track the three markers of a recording",
                              description="Track the ABU centre, CD and ball markers through a "
                                          "recording and write tracks.csv.")
    p.add_argument("input", help="folder of frames, multi-page TIFF, .npy stack or video")
    p.add_argument("--out", required=True, help="output folder")
    add_overwrite(p)
    _add_tracking_options(p)
    p.set_defaults(func=cmd_track)

    p = subparsers.add_parser("measure", help="interval on mu from a recording or tracks",
                              description="Track (or read tracks with --tracks), compute theta, "
                                          "beta, omega, omega_dot and the interval "
                                          "[mu_low, mu_high] with its error analysis.")
    p.add_argument("input", help="recording (see 'abu track'), or with --tracks a CSV with "
                                 "time,x_center,y_center,x_cd,y_cd,x_ball,y_ball")
    p.add_argument("--out", required=True, help="output folder")
    add_overwrite(p)
    p.add_argument("--tracks", action="store_true", help="INPUT is a tracks CSV")
    _add_tracking_options(p)
    p.add_argument("--l", type=float, default=DEFAULT_L,
                   help=f"radius of the ball centre's path [m] (default {DEFAULT_L:g})")
    p.add_argument("--d", type=float, default=DEFAULT_D,
                   help=f"ball diameter [m] (default {DEFAULT_D:g})")
    p.add_argument("--estimator", choices=["savgol", "report"], default="savgol",
                   help="omega / omega_dot estimator (default savgol)")
    p.add_argument("--sg-window-s", type=float, default=0.042,
                   help="Savitzky-Golay window [s] (default 0.042, degree 9)")
    p.add_argument("--poly-degree", type=int, default=10,
                   help="degree of the report estimator's polynomial (default 10)")
    p.add_argument("--trim-s", type=float, default=None,
                   help="time excluded at each end [s] (default: savgol 0, report 0.05)")
    p.add_argument("--k-sigma", type=float, default=3.0,
                   help="error-bar multiple for the bounds and the slip threshold (default 3)")
    p.add_argument("--lower", choices=["creep", "band"], default="creep",
                   help="how the last surely-stuck time is found (default creep)")
    p.add_argument("--no-harmonic", action="store_true",
                   help="do not remove the lighting harmonic from beta")
    p.add_argument("--harmonic-phase", choices=["ball", "cd"], default="ball",
                   help="phase of the harmonic: ball angle (default) or theta")
    p.add_argument("--mc-draws", type=int, default=0,
                   help="Monte Carlo draws of tracking noise through the running-max interval "
                        "(default 0: the model's profile likelihood is the uncertainty)")
    p.add_argument("--confidence", type=float, default=0.95,
                   help="level of the confidence sets on mu and mu_d (default 0.95)")
    p.add_argument("--seed", type=int, default=0, help="Monte Carlo seed (default 0)")
    p.add_argument("--json", action="store_true", help="print the summary as JSON on stdout")
    p.add_argument("--no-plots", action="store_true", help="do not write the PNG figures")
    p.add_argument("--drive", default=None, help="drive.json of 'abu identify' of the setup that "
                   "made the recording (recorded in summary.json for 'abu next')")
    from .cli_camera import add_camera_option, register as register_camera
    add_camera_option(p)
    p.set_defaults(func=cmd_measure)

    p = subparsers.add_parser("measure-summary", help="combine the intervals of several records",
                              description="Histogram (report fig. 5.11), union / majority / "
                                          "common ranges and a Turnbull estimate from several "
                                          "summary.json files.")
    p.add_argument("summaries", nargs="+", help="summary.json files of 'abu measure' (or a CSV "
                                                "with columns mu_low,mu_high)")
    p.add_argument("--out", required=True, help="output folder")
    add_overwrite(p)
    p.add_argument("--bins", type=int, default=100, help="grid points of the histogram")
    p.add_argument("--json", action="store_true", help="print the result as JSON on stdout")
    p.set_defaults(func=cmd_measure_summary)

    p = subparsers.add_parser("render", help="render the digital twin of the experiment",
                              description="Simulate the report's experiment and render it as a "
                                          "high-speed camera recording (frames.tif, truth.csv, "
                                          "meta.json).")
    p.add_argument("--out", required=True, help="output folder")
    add_overwrite(p)
    from .twin import add_render_arguments
    add_render_arguments(p)
    if "--fmu-dir" not in {s for a in p._actions for s in a.option_strings}:
        p.add_argument("--fmu-dir", default=None,
                       help="folder with the FMUs (built there if missing; default: a "
                            "temporary build)")
    p.add_argument("--drive", default=None, help="drive.json of 'abu identify': its zeta, omega_n "
                   "and tau_motor replace --zeta, --omega-n, --tau-motor")
    p.add_argument("--quiet", action="store_true", help="no messages on stderr")
    p.set_defaults(func=cmd_render)
    register_camera(subparsers)


def build_parser() -> argparse.ArgumentParser:
    """A parser with only the measurement commands (the stand-alone entry point)."""
    parser = AbuArgumentParser(prog="abu", description="ABU friction measurement commands")
    sub = parser.add_subparsers(dest="command", required=True)
    register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run one measurement command; AbuError -> message on stderr and status 2."""
    return run_command(build_parser, argv, rename=_rename)


#: Library parameter names -> the options of the measurement commands.
OPTION_OF = {"sg_window_s": "--sg-window-s", "window": "--window", "trim_s": "--trim-s",
             "poly_degree": "--poly-degree", "k_sigma": "--k-sigma", "mc_draws": "--mc-draws",
             "fps": "--fps", "bins": "--bins", "l": "--l", "d": "--d", "seeds": "--seeds",
             "method": "--method"}


def _rename(args: argparse.Namespace, exc: ParameterError) -> ParameterError:
    return option_error(exc, OPTION_OF, getattr(args, "_parser", None))


if __name__ == "__main__":
    sys.exit(main())
