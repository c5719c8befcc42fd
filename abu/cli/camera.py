"""``abu calibrate-camera`` and the ``--camera`` step of ``abu measure``.

``abu calibrate-camera VIEWS --pattern 9x6 --out camera.json``: VIEWS is a folder of images (or
a multi-page TIFF / .npy stack) of a chessboard plate lying in the ABU plane, moved and turned
between views (``abu render --scenario random --calibration-views K`` writes such a folder for
the twin). The camera file is written atomically; bad input is one line and exit 2.

``abu measure --camera camera.json``: every tracked pixel position (all markers, both ball
reflections through the ball position they give) is undistorted before the angles are taken, and
the prior bound on theta's first harmonic (``InferenceOptions.theta_harmonic_rad``) comes from
the calibration (:func:`measurement.imaging.camera.theta_harmonic_prior`) instead of the family prior.
"""
from __future__ import annotations

import argparse
import sys
import numpy as np

from abu.cli.common import add_overwrite, in_range
from abu.cli.output_tx import output_file

from measurement.imaging import camera as cam_mod
from measurement.imaging import camera_calibration as calib


def cmd_calibrate_camera(args: argparse.Namespace) -> int:
    """Find the chessboard in every view, calibrate, write the camera file."""
    from measurement.imaging.frames_io import read_recording
    from measurement.report.json_text import dumps

    pattern = calib.parse_pattern(args.pattern)
    focal = None if args.focal_px is None else in_range(
        "--focal-px", args.focal_px, 1.0, 1e6, "px", "the fixed focal length (any fixed value "
        "gives the same undistortion; default the half diagonal)")
    square = in_range("--square", args.square, 1e-9, 1e9, "", "the side of a square (any unit)")
    rec = read_recording(args.views)
    names = rec.frame_names or [f"{rec.source} frame {i}" for i in range(len(rec))]
    cam, rows = calib.calibrate_from_frames(np.asarray(rec.frames), pattern, focal_px=focal,
                                            square=square, names=names)
    cam.extra["source"] = rec.source
    with output_file(args.out, overwrite=args.overwrite) as tmp:
        cam_mod.write_camera(tmp, cam)
    if args.json:
        sys.stdout.write(dumps(cam.to_dict()))
    else:
        k, dc = cam.camera_matrix, cam.dist_coeffs
        print(f"camera from {cam.n_views} of {len(rows)} views ({cam.n_corners} corners): "
              f"k1 = {dc[0]:.5g}, k2 = {dc[1]:.5g}, centre ({k[0, 2]:.2f}, {k[1, 2]:.2f}) px, "
              f"f = {k[0, 0]:.1f} px (fixed), reprojection RMS {cam.rms_px:.4f} px -> {args.out}")
    return 0


def add_camera_option(p: argparse.ArgumentParser) -> None:
    p.add_argument("--camera", default=None,
                   help="camera.json of 'abu calibrate-camera': undistort the tracked positions "
                        "and take theta's harmonic prior from the calibration")


def register(subparsers) -> None:
    """Add ``calibrate-camera`` to ``subparsers``."""
    p = subparsers.add_parser(
        "calibrate-camera", help="lens calibration from chessboard views in the ABU plane",
        description="Find the chessboard's inner corners in every view (OpenCV "
                    "findChessboardCorners + cornerSubPix), fit the radial lens distortion and "
                    "its centre (calibrateCamera; focal length fixed, square pixels, no "
                    "tangential terms, k3 = 0) and write camera.json for 'abu measure --camera'.")
    p.add_argument("views", help="folder of views (PNG, BMP, TIFF), multi-page TIFF or .npy")
    p.add_argument("--pattern", default="9x6",
                   help="inner corners per row x per column (default 9x6: 10x7 squares)")
    p.add_argument("--out", required=True, help="camera file to write (JSON)")
    add_overwrite(p)
    p.add_argument("--focal-px", type=float, default=None,
                   help="fixed focal length [px] (default: half the image diagonal)")
    p.add_argument("--square", type=float, default=1.0,
                   help="side of a square (any unit; default 1)")
    p.add_argument("--json", action="store_true", help="print the camera file on stdout")
    p.set_defaults(func=cmd_calibrate_camera)
