"""Measurement commands of the ``abu`` command line: ``track``, ``measure``, ``measure-summary``.

Each parses and checks its options, calls :mod:`measurement.pipeline` and writes; the printed text
of the summaries is :mod:`measurement.report.summary_text`. :mod:`abu.cli.main` builds the
parser and calls :func:`register`; every subcommand sets ``func`` (``args -> exit status``).
Errors derived from :class:`abu_model.errors.AbuError` are printed by the main program, which
exits with status 2. Outputs are computed completely before anything is written, and every file
is written atomically, so a failing command leaves no half-written file behind.
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from abu_model.atomic_io import atomic_write_text
from abu_model.errors import AbuError, ParameterError
from abu_model.json_text import dumps
from abu.cli.common import (MAX_BINS, add_figure_format, add_overwrite, given, in_range,
                            integer_range,
                            log as _log)
from abu.cli.output_tx import check_not_inside, output_folder

from abu.cli.options_drive_model import add_drive_model_options, drive_model_from_args
from abu.cli.checks_measure import check_analysis_options, check_tracking_options
from measurement.pipeline import (DEFAULT_D_M, DEFAULT_L_M, SUMMARY_KIND,  # noqa: F401
                                  SUMMARY_VERSION, TrackingSettings, measure_recording,
                                  measure_tracks_file, track_recording, write_measurement,
                                  write_tracks)
from measurement.report.summary_text import describe_combined, describe_measurement

COMBINED_KIND = "abu-measure-summary-combined"
DEFAULT_L = DEFAULT_L_M
DEFAULT_D = DEFAULT_D_M


# ------------------------------------------------------------------------------ helpers

def _positive(name: str, value: float | None, unit: str) -> float | None:
    if value is None:
        return None
    if not (math.isfinite(value) and value > 0):
        raise ParameterError(name, value, f"a finite number > 0 {unit}".rstrip())
    return float(value)


def _warn(text: str) -> None:
    """A warning: one line on stderr, even with ``--quiet``."""
    print(text, file=sys.stderr)


def _tracking_settings(args: argparse.Namespace) -> TrackingSettings:
    """The tracker's settings from the options (--seeds parsed here, named in its errors)."""
    seeds = None
    if args.seeds is not None:
        from measurement.imaging.markers import parse_seeds
        try:
            seeds = parse_seeds(args.seeds)
        except AbuError as exc:
            raise AbuError(f"--seeds: {exc}") from None
    return TrackingSettings(seeds_px=seeds, dark_markers=args.dark_markers, method=args.method,
                            window_px=args.window, ball_reflections=args.ball_reflections,
                            ball_method=args.ball_method, progress=args.progress,
                            edge_step=(True if args.edge_step else
                                       False if args.no_edge_step else None))


# ------------------------------------------------------------------------------ track

def cmd_track(args: argparse.Namespace) -> int:
    """``abu track INPUT --out DIR``: marker tracks only (tracks.csv, tracking.json)."""
    check_tracking_options(args)
    fps = _positive("--fps", args.fps, "frames/s")
    settings = _tracking_settings(args)
    out = Path(args.out)
    check_not_inside(out, [args.input])
    with output_folder(out, overwrite=args.overwrite) as tmp:
        tracks = track_recording(args.input, fps_hz=fps, settings=settings,
                                 log=lambda text: _log(args, text), warn=_warn)
        write_tracks(tracks, tmp)
    _log(args, f"wrote {out / 'tracks.csv'} ({tracks.info['frames']} frames, lost "
               f"{tracks.info['lost_frames']})")
    return 0


# ------------------------------------------------------------------------------ measure

#: ``--lighting-models`` -> the second lighting model's harmonic orders (() none; None: by
#: the ball's reflections, ``measurement.inference.lighting_models.alternative_orders``).
LIGHTING_MODELS = {"auto": None, "one": (), "two": (1, 2, 3, 4, 5, 6)}

def _analysis_options(args: argparse.Namespace):
    from measurement.inference.analysis import AnalysisOptions
    from measurement.inference.infer_mu import InferenceOptions
    from measurement.inference.running_max import IntervalOptions
    check_analysis_options(args)
    return AnalysisOptions(
        estimator=args.estimator, sg_window_s=_positive("--sg-window-s", args.sg_window_s, "s"),
        poly_degree=args.poly_degree, trim_s=args.trim_s, harmonic=not args.no_harmonic,
        harmonic_phase=args.harmonic_phase,
        harmonic_orders_alternative=LIGHTING_MODELS[args.lighting_models],
        interval=IntervalOptions(k_sigma=_positive("--k-sigma", args.k_sigma, ""),
                                 lower=args.lower),
        mc_draws=args.mc_draws, seed=args.seed,
        inference=InferenceOptions(confidence=in_range(
            "--confidence", args.confidence, 0.5, 0.9999, "", "a probability, e.g. 0.95"),
            max_fit_samples=integer_range(
                "--max-fit-samples", args.max_fit_samples, 256, 16384,
                "samples of the model fit's window; its noise covariance takes ~50 n^2 bytes")),
        kinematics=args.kinematics, drive_model=drive_model_from_args(args),
        line_time_s=in_range("--line-time", args.line_time, -1e-3, 1e-3, "s",
                             "a rolling shutter's read-out time per sensor row"))


def cmd_measure(args: argparse.Namespace) -> int:
    """``abu measure INPUT --out DIR``: track (or read tracks) and analyse."""
    check_tracking_options(args)
    drive = None
    if getattr(args, "drive", None):  # a bad drive.json fails before the tracking
        from controller.drive import load_drive
        drive = load_drive(args.drive).to_dict()
    camera = None
    if getattr(args, "camera", None):  # so does a bad camera file (read once, used later)
        from measurement.imaging.camera import read_camera
        camera = read_camera(args.camera)
    l = in_range("--l", _positive("--l", args.l, "m"), 1e-4, 1.0, "m",
                 "radius of the ball centre's path; a CD drive's is 1.15e-2 m")
    d = in_range("--d", _positive("--d", args.d, "m"), 1e-5, 0.1, "m",
                 "ball diameter; the report's is 3e-3 m")
    fps_opt = _positive("--fps", args.fps, "frames/s")
    options = _analysis_options(args)
    settings = None if args.tracks else _tracking_settings(args)
    out = Path(args.out)
    check_not_inside(out, [args.input])
    common = {"l_m": l, "d_m": d, "options": options, "camera": camera,
              "camera_path": getattr(args, "camera", None), "drive": drive}
    with output_folder(out, overwrite=args.overwrite) as tmp:
        if args.tracks:
            result = measure_tracks_file(
                args.input, fps_hz=fps_opt, ball_reflections=(
                    args.ball_reflections if given(args, "--ball-reflections") else None),
                **common)
        else:
            result = measure_recording(args.input, fps_hz=fps_opt, tracking=settings,
                                       log=lambda text: _log(args, text), warn=_warn,
                                       **common)
        write_measurement(result, tmp, plots=not args.no_plots,
                          figure_format=args.figure_format)
    if args.json:
        sys.stdout.write(dumps(result.summary))
    else:
        print(describe_measurement(result.summary))
    return 0


# ------------------------------------------------------------------------------ summary of runs

def cmd_measure_summary(args: argparse.Namespace) -> int:
    """``abu measure-summary SUMMARY.json ... --out DIR``: combine several records' intervals."""
    from measurement.report.multi import combine_summaries, plot_histogram, read_intervals

    out = Path(args.out)
    integer_range("--bins", args.bins, 2, MAX_BINS, "grid points of the drawn histogram; the "
                  "counts are exact at any grid")
    check_not_inside(out, args.summaries)
    intervals = read_intervals(args.summaries)
    with output_folder(out, overwrite=args.overwrite) as tmp:
        result = {"kind": COMBINED_KIND, "format_version": SUMMARY_VERSION,
                  **combine_summaries(intervals, bins=args.bins)}
        text = dumps(result)
        plot_histogram(result, tmp / "histogram", args.figure_format)
        atomic_write_text(tmp / "measure_summary.json", text)
    if args.json:
        sys.stdout.write(text)
    else:
        print(describe_combined(result))
    return 0


# ------------------------------------------------------------------------------ parser

def _add_tracking_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--fps", type=float, default=None,
                   help="frame rate of the recording [frames/s]. Default: the rate the file "
                        "states (Photron CIH/CIHX, Phantom CINE, a TIFF of 'abu render'); "
                        "required for video (its container holds a playback rate), .npy stacks, "
                        "folders of frames and other TIFFs; given, it overrides the file's (with "
                        "a warning). With --tracks the CSV's time column is used")
    p.add_argument("--seeds", default=None,
                   help="marker positions in frame 0, 'x,y;x,y;x,y' [px] (x = column, y = row) "
                        "in the order ABU centre; CD marker; ball. Default: found automatically")
    p.add_argument("--dark-markers", action="store_true",
                   help="markers are darker than their surroundings")
    p.add_argument("--method", default="isocontour",
                   help="centre-finding method: isocontour (default), report, moments")
    p.add_argument("--window", type=int, default=None,
                   help="tracking window [px]. Default: sized from the markers found in the "
                        "first frames: 30 px where that holds every marker (its radius with "
                        "blur, a 2 px border and twice its motion a frame, each side) without "
                        "reaching another marker or the ball's path; else the nearest size "
                        "that does (recorded in summary.json, input.window_choice)")
    step = p.add_mutually_exclusive_group()
    step.add_argument("--edge-step", action="store_true",
                      help="isocontour: end with one least-squares step of a blurred-disk model "
                           "on the edge pixels (17-30 %% less RMS error on rendered markers). "
                           "Default: on the centre and CD markers with --ball-reflections 1, "
                           "off with 2; never on the ball's outline (2). This option turns it "
                           "on for every marker the contour fit measures")
    step.add_argument("--no-edge-step", action="store_true",
                      help="isocontour: the contour's circle fit alone, without the edge step")
    p.add_argument("--ball-reflections", type=int, choices=[1, 2], default=1,
                   help="bright reflections on the ball: 1 (default; one marker at the ball) "
                        "or 2 (the report's two-spot lighting, sec. 5.2); with abu measure "
                        "--tracks: how the tracked ball looked (2: both lighting models by "
                        "default)")
    p.add_argument("--ball-method", choices=["outline", "pair"], default="outline",
                   help="with --ball-reflections 2: outline (default; circle fit to the ball's "
                        "silhouette) or pair (the report's way: the mean of the reflections)")
    p.add_argument("--progress", action="store_true", help="progress bar while tracking")
    p.add_argument("--quiet", action="store_true", help="no messages on stderr")


def register(subparsers) -> None:
    """Add ``track``, ``measure`` and ``measure-summary`` to ``subparsers``."""
    p = subparsers.add_parser("track", help="track the three markers of a recording",
                              description="Track the ABU centre, CD and ball markers through a "
                                          "recording and write tracks.csv.")
    p.add_argument("input", help="Photron MRAW (.cih/.cihx/.mraw), Phantom .cine, multi-page "
                                 "TIFF, folder of frames, .npy stack or video")
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
    p.add_argument("--lighting-models", choices=sorted(LIGHTING_MODELS), default="auto",
                   help="one: the lighting harmonics of orders 1-4 removed from beta; two: "
                        "also orders 1-6, and the union of both models' sets where they "
                        "disagree at the slip (a second inference, ~0.1 s); auto (default): "
                        "two with --ball-reflections 2 (with --tracks: as the tracked ball "
                        "looked), one otherwise")
    p.add_argument("--mc-draws", type=int, default=0,
                   help="Monte Carlo draws of tracking noise through the running-max interval "
                        "(default 0: the model's profile likelihood is the uncertainty)")
    p.add_argument("--confidence", type=float, default=0.95,
                   help="level of the confidence sets on mu and mu_d (default 0.95)")
    p.add_argument("--line-time", type=float, default=0.0,
                   help="a rolling shutter's read-out time per sensor row [s] (negative: the "
                        "bottom row first; default 0: a global shutter): the tracked positions "
                        "are brought back to the frame times")
    p.add_argument("--max-fit-samples", type=int, default=3072,
                   help="most samples of the model fit's window (default 3072); a longer one "
                        "(a late slip in a long record) is cut around the slip's first move: "
                        "its noise covariance costs n^2 memory and n^3 time (8192: ~3 GB)")
    p.add_argument("--seed", type=int, default=0, help="Monte Carlo seed (default 0)")
    p.add_argument("--json", action="store_true", help="print the summary as JSON on stdout")
    p.add_argument("--no-plots", action="store_true", help="do not write the figures")
    add_figure_format(p)
    p.add_argument("--drive", default=None, help="drive.json of 'abu identify' of the setup that "
                   "made the recording (recorded in summary.json for 'abu next'; with "
                   "--kinematics drive-model also its loop model)")
    add_drive_model_options(p)
    from abu.cli.camera import add_camera_option
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
    add_figure_format(p)
    p.set_defaults(func=cmd_measure_summary)



#: Library parameter names -> the options of the measurement commands.
OPTION_OF = {"sg_window_s": "--sg-window-s", "window": "--window", "trim_s": "--trim-s",
             "poly_degree": "--poly-degree", "k_sigma": "--k-sigma", "mc_draws": "--mc-draws",
             "fps": "--fps", "bins": "--bins", "l": "--l", "d": "--d", "seeds": "--seeds",
             "method": "--method", "max_fit_samples": "--max-fit-samples",
             "line_time_s": "--line-time"}
