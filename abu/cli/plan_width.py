"""The width model's constants of ``abu design`` / ``abu next``: the set-up of earlier
recordings (``--noise-from``, or the summaries ``abu next`` combines) and ``--kinematics``."""
from __future__ import annotations

import argparse
import json
from pathlib import Path

from abu_model.errors import ParameterError


def add_width_options(g: argparse._ArgumentGroup) -> None:
    """``--noise-from`` and ``--kinematics`` of design and next."""
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
    return constants if kinematics is None else replace(constants, kinematics=kinematics)
