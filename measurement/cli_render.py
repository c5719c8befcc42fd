"""``abu render``: the camera twin of the report's experiment, or one recording of the harsh
random family (``--scenario random --seed N``, optionally with chessboard views for ``abu
calibrate-camera``), written into a fresh output folder."""
from __future__ import annotations

import argparse
from pathlib import Path

from abu_model.errors import ParameterError
from harness.cli_common import integer_range, log as _log
from harness.output_tx import output_folder

from .cli_checks import check_render_options


def cmd_render(args: argparse.Namespace) -> int:
    """``abu render --out DIR``: render the digital twin of the report's experiment."""
    check_render_options(args)
    if getattr(args, "fmu_dir", None):
        from harness.cli_checks import check_fmu_dir
        check_fmu_dir("--fmu-dir", args.fmu_dir, ("AbuBall", "SpeedController", "Staircase"))
    out = Path(args.out)
    if getattr(args, "scenario", "report") == "random":
        if getattr(args, "drive", None):
            raise ParameterError("--drive", args.drive, "no --drive with --scenario random "
                                 "(its drive is drawn at random)")
        if args.calibration_views:
            from .calibration_target import MAX_VIEWS
            from .camera_calibration import MIN_VIEWS  # fewer: calibrate-camera refuses them
            integer_range("--calibration-views", args.calibration_views, MIN_VIEWS, MAX_VIEWS,
                          "chessboard views for 'abu calibrate-camera'")
        from .scenario import random_scenario, render_scenario
        scn = random_scenario(args.seed, size=args.size, lighting=args.lighting,
                              n_frames=args.frames)
        with output_folder(out, overwrite=args.overwrite) as tmp:
            render_scenario(tmp, scn)
            if args.calibration_views:  # chessboard views through the same lens and sensor
                from .calibration_target import write_views
                write_views(tmp / "calibration", scn.optics, scn.width, scn.height,
                            args.calibration_views, scn.seed, pixel_size_m=scn.pixel_size)
        _log(args, f"wrote the random twin recording (seed {args.seed}, mu = {scn.ball.mu:.5g}, "
                   f"{scn.drive.kind} drive, {scn.lighting.kind} lighting) to {out}")
        return 0
    if getattr(args, "calibration_views", 0):
        raise ParameterError("--calibration-views", args.calibration_views, "0 with --scenario "
                             "report (its lens is ideal; use --scenario random)")
    from .twin import render_twin, twin_settings_from_args
    from harness.cli_plan import apply_drive_to_args
    apply_drive_to_args(args)
    settings = twin_settings_from_args(args)
    with output_folder(out, overwrite=args.overwrite) as tmp:
        render_twin(tmp, settings, fmu_dir=getattr(args, "fmu_dir", None))
    _log(args, f"wrote the twin recording to {out}")
    return 0
