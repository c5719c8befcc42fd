"""The lens calibration of the benchmarks' ``--camera`` runs: the chessboard views of a rendered
scenario's own optics (``twin.calibration_target``) and ``abu calibrate-camera`` on them, as a
user who calibrates the camera before recording would. Used by ``bench_coverage.py`` and
``bench_width_floor.py``.
"""
from __future__ import annotations

import io
import json
import math
import time
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path

import numpy as np

from abu.cli.main import main as abu_main
from twin.calibration_target import render_views


def calibrate(scn, work: Path, views: int) -> tuple[Path, dict]:
    """Render the scenario's calibration views (same optics), run ``abu calibrate-camera``.

    Returns:
        (camera.json written in ``work``, {seconds, reprojection RMS [px], k1 and k2 errors,
        optical centre error [px]} against the scenario's true optics).
    """
    t0 = time.perf_counter()
    frames, _, _ = render_views(scn.optics, scn.width, scn.height, views, scn.seed)
    stack = work / f"cal{scn.seed}.npy"
    np.save(stack, frames)
    cam = work / f"cam{scn.seed}.json"
    err = io.StringIO()
    with redirect_stdout(io.StringIO()), redirect_stderr(err):
        status = abu_main(["calibrate-camera", str(stack), "--pattern", "9x6", "--out",
                           str(cam), "--overwrite"])
    stack.unlink()
    if status != 0:
        raise RuntimeError(f"calibrate-camera failed: {err.getvalue().strip()}")
    c = json.loads(cam.read_text())
    o = scn.optics
    return cam, {"cal_s": time.perf_counter() - t0, "cal_rms_px": c["reprojection_rms_px"],
                 "cal_k1_err": c["dist_coeffs"][0] - o.k1, "cal_k2_err": c["dist_coeffs"][1] - o.k2,
                 "cal_centre_err_px": math.hypot(c["camera_matrix"][0][2] - o.optical_centre[0],
                                                 c["camera_matrix"][1][2] - o.optical_centre[1])}
