"""The width model's constants of ``abu design`` / ``abu next``: the set-up of earlier
recordings (``--noise-from``, or the summaries ``abu next`` combines), ``--kinematics``, and
the lens prior of a calibrated camera (``--camera``, ``--cd-circle``)."""
from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

from abu_model.errors import ParameterError

#: Without ``--cd-circle`` the CD marker is assumed to circle the image centre at this share
#: of the smaller image side (the report's framing, the ABU filling the frame: the twin's
#: family has 0.35-0.41 of 256 px)
CD_RADIUS_SHARE = 0.37


def add_width_options(g: argparse._ArgumentGroup) -> None:
    """``--noise-from``, ``--kinematics``, ``--camera`` and ``--cd-circle`` of design and next."""
    g.add_argument("--noise-from", nargs="+", default=None, metavar="SUMMARY",
                   help="abu measure summary.json of earlier recordings with this camera and "
                        "lighting: their theta and beta noise, their lens prior (a summary "
                        "measured with --camera) and their kinematics set the predicted width "
                        "(default: the calibrated typical camera, uncalibrated lens; abu next "
                        "uses the summaries it combines)")
    g.add_argument("--kinematics", choices=["savgol", "drive-model"], default=None,
                   help="the kinematics 'abu measure' will use on the run: savgol (its "
                        "default) or drive-model (the staircase and drive stated); default: "
                        "those of the --noise-from summaries, else savgol")
    g.add_argument("--camera", default=None, metavar="CAMERA",
                   help="camera.json of 'abu calibrate-camera' the run will be measured with "
                        "('abu measure --camera'): the calibration's lens prior at --cd-circle "
                        "replaces the uncalibrated one (and that of any summary)")
    g.add_argument("--cd-circle", default=None, metavar="X,Y,R",
                   help="with --camera: the ABU axis X,Y and the CD marker's distance R from "
                        "it in the run's frames [px] (a measured summary states them: "
                        "camera.axis_px, camera.r_cd_px); default: the image centre and "
                        f"{CD_RADIUS_SHARE:g} x the smaller image side")


def width_constants(args: argparse.Namespace, summaries: list[str] | None):
    """The width model's constants: the set-up of ``--noise-from`` (else, for ``abu next``, of
    the summaries it combines; else the calibrated defaults), ``--kinematics`` over it."""
    from dataclasses import replace

    from harness.planning.width_model import CALIBRATED, with_recorded_setup

    noise_from = args.noise_from or []
    option = "--noise-from" if noise_from else "summaries"
    paths = noise_from or [p for p in summaries or [] if Path(p).suffix.lower() == ".json"]
    found = []
    for p in paths:
        try:
            obj = json.loads(Path(p).read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            raise ParameterError(option, p, f"a readable abu measure summary.json ({exc})"
                                 ) from None
        if not isinstance(obj, dict):
            raise ParameterError(option, p, "a JSON object (abu measure summary.json)")
        if obj.get("kind") == "abu-measure-summary":
            found.append(obj)
        elif noise_from:
            raise ParameterError("--noise-from", p, "an abu measure summary.json (kind "
                                 f"abu-measure-summary, not {obj.get('kind')!r})")
    constants = with_recorded_setup(CALIBRATED, found)
    kinematics = getattr(args, "kinematics", None)
    if kinematics is not None:
        constants = replace(constants, kinematics=kinematics)
    lens = camera_lens_prior(getattr(args, "camera", None), getattr(args, "cd_circle", None))
    if lens is not None:
        constants = replace(constants, theta_harmonic_rad=lens[0], lens_source="camera",
                            lens_note=lens[1])
    return constants


def _cd_circle(text: str, size: tuple[int, int]) -> tuple[float, float, float]:
    """``X,Y,R`` [px] of ``--cd-circle``, inside a ``size`` (width, height) image."""
    w, h = size
    expected = (f"X,Y,R [px]: the axis inside the camera's {w}x{h} px image and the CD "
                "marker's distance from it, R > 0, the circle inside the image")
    try:
        x, y, r = (float(v) for v in text.split(","))
    except ValueError:
        raise ParameterError("--cd-circle", text, expected) from None
    if not all(math.isfinite(v) for v in (x, y, r)) or r <= 0 \
            or not (r - 0.5 <= x <= w - 0.5 - r and r - 0.5 <= y <= h - 0.5 - r):
        raise ParameterError("--cd-circle", text, expected)
    return x, y, r


def camera_lens_prior(camera: str | None, cd_circle: str | None) -> tuple[float, str] | None:
    """(the lens prior on theta's harmonics [rad], how it was obtained) of ``--camera`` at
    ``--cd-circle`` (:func:`measurement.imaging.camera.theta_harmonic_prior`, what ``abu
    measure --camera`` states for a recording with that circle); None without ``--camera``."""
    if camera is None:
        if cd_circle is not None:
            raise ParameterError("--cd-circle", cd_circle, "given with --camera (the circle "
                                 "places the calibrated lens's error)")
        return None
    from measurement.imaging.camera import read_camera, theta_harmonic_prior

    cam = read_camera(camera)
    w, h = cam.image_size
    if cd_circle is None:
        x, y, r = (w - 1) / 2.0, (h - 1) / 2.0, CD_RADIUS_SHARE * min(w, h)
        where = (f"the CD marker assumed to circle the image centre at {r:.0f} px; state "
                 "yours with --cd-circle X,Y,R")
    else:
        x, y, r = _cd_circle(cd_circle, (w, h))
        where = f"the CD marker circling ({x:g}, {y:g}) px at {r:g} px"
    prior = float(theta_harmonic_prior(cam, (x, y), r)["theta_harmonic_rad"])
    return prior, f"{camera}, {where}"
