"""The frame rate of a recording: what the file states, what the user gives, and which is used.

Where a recording's rate comes from (:func:`measurement.imaging.frames_io.read_recording` fills
``Recording.fps_hz`` / ``fps_source``):

* a camera file's header (Photron CIH/CIHX ``Record Rate(fps)``, Phantom CINE ``FrameRate``);
* our own renders: ``abu render`` writes the rate into the TIFF it writes (tifffile's JSON
  ImageDescription, ``{"kind": "abu-frames", "fps_hz": ...}``, :data:`TIFF_KIND`); a TIFF rendered
  before that is recognised by the ``meta.json`` beside it (``kind`` ``abu-render-meta``, whose
  ``files.frames`` names the TIFF);
* nothing else: ``.npy`` stacks, folders of frames and TIFFs without our metadata state no rate.

Video containers: OpenCV reports the container's rate, but a high-speed camera's video export
stores a *playback* rate (typically 25 or 30 frames/s for a recording made at thousands of
frames/s), and nothing in the file tells the two apart. Taking it would put the time axis off by
a factor of ~150 without a word, so it does **not** count: a video needs ``--fps``, and the
container's rate is only reported (``video_container_fps_hz``) and named in the message.

:func:`resolve_frame_rate` decides: the given rate overrides the file's (with a warning when
they differ by more than :data:`RATE_TOLERANCE`); no rate at all is an error naming the option
and the file.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from abu_model.errors import ParameterError
from abu_model.params import MAX_CAMERA_FPS_HZ

from measurement.imaging.recording_checks import RecordingError

#: ``kind`` of the JSON metadata our TIFF writer stores (frame rate, first-frame time).
TIFF_KIND = "abu-frames"
#: ``kind`` of a rendered recording's meta.json (twin.report_twin.RENDER_META_KIND).
RENDER_META_KIND = "abu-render-meta"
#: Relative difference of a given and a stated rate reported as a disagreement.
RATE_TOLERANCE = 1e-6
#: Plausible frame rates [frames/s] (the one limit of readers, options and plans).
MAX_FPS_HZ = MAX_CAMERA_FPS_HZ


class MissingFrameRateError(RecordingError):
    """Neither the recording nor the user states a frame rate."""


@dataclass(frozen=True)
class FrameRate:
    """The frame rate used for a recording.

    Attributes:
        fps_hz: frames per second [1/s].
        source: where it came from (the header field, the option, the file).
        stated_hz: the rate the file states, if any [1/s] (differs from ``fps_hz`` when the
            user overrode it).
    """

    fps_hz: float
    source: str
    stated_hz: float | None = None


def _checked_rate(value: Any, where: str, field: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or not (math.isfinite(value) and 0 < value <= MAX_FPS_HZ):
        raise RecordingError(f"{where}: '{field}' is {value!r}; expected a frame rate > 0 and "
                             f"<= {MAX_FPS_HZ:g} frames/s")
    return float(value)


def _checked_time(value: Any, where: str, field: str) -> float | None:
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise RecordingError(f"{where}: '{field}' is {value!r}; expected a finite time [s]")
    return float(value)


def tiff_metadata(frame_rate_hz: float | None, first_frame_time_s: float | None
                  ) -> dict[str, Any]:
    """The JSON metadata our TIFF writer stores (empty without a rate)."""
    if frame_rate_hz is None:
        return {}
    meta = {"kind": TIFF_KIND, "fps_hz": _checked_rate(frame_rate_hz, "TIFF metadata", "fps_hz")}
    if first_frame_time_s is not None:
        meta["first_frame_time_s"] = _checked_time(first_frame_time_s, "TIFF metadata",
                                                   "first_frame_time_s")
    return meta


def rate_from_tiff(p: Path, tif) -> tuple[float | None, str | None, float | None]:
    """(fps_hz, fps_source, first_frame_time_s) from our metadata in an open TIFF, else the
    ``meta.json`` beside it (a render written before the TIFF carried it), else Nones."""
    try:
        shaped = tif.shaped_metadata if tif.is_shaped else None
    except Exception:  # a damaged description: no metadata, the pixels decide
        shaped = None
    meta = shaped[0] if shaped else None
    if isinstance(meta, dict) and meta.get("kind") == TIFF_KIND:
        where = f"TIFF '{p}' ImageDescription"
        return (_checked_rate(meta.get("fps_hz"), where, "fps_hz"),
                f"TIFF ImageDescription 'fps_hz' ({TIFF_KIND}, written by abu render)",
                _checked_time(meta.get("first_frame_time_s"), where, "first_frame_time_s"))
    return rate_from_render_meta(p)


def rate_from_render_meta(p: Path) -> tuple[float | None, str | None, float | None]:
    """(fps_hz, fps_source, first_frame_time_s) from a render's ``meta.json`` beside ``p``
    that names ``p`` as its frames; Nones when there is none (or it is not a render's)."""
    meta_path = p.parent / "meta.json"
    try:
        meta = json.loads(meta_path.read_text(encoding="utf-8"))
    except (OSError, ValueError, UnicodeDecodeError):
        return None, None, None
    if not (isinstance(meta, dict) and meta.get("kind") == RENDER_META_KIND
            and isinstance(meta.get("files"), dict) and meta["files"].get("frames") == p.name):
        return None, None, None
    where = f"'{meta_path}'"
    return (_checked_rate(meta.get("fps"), where, "fps"), f"{meta_path.name} 'fps' beside "
            f"{p.name} (abu render)",
            _checked_time(meta.get("time_first_frame_s"), where, "time_first_frame_s"))


def resolve_frame_rate(stated_hz: float | None, stated_source: str | None, given_hz: float | None,
                       *, source: str, option: str = "--fps",
                       warn: Callable[[str], None] | None = None,
                       container_hz: float | None = None) -> FrameRate:
    """The rate to use: ``given_hz`` if given (warning through ``warn`` when the file states a
    different one), else the file's.

    Args:
        stated_hz, stated_source: what the recording states (None: nothing; ``stated_source``
            may then say why).
        given_hz: the user's rate [frames/s] or None.
        source: the recording, for messages.
        option: how the user gives the rate (``--fps``, ``fps_hz``).
        container_hz: a video container's (playback) rate, named in the message.

    Raises:
        ParameterError: ``given_hz`` not a plausible rate.
        MissingFrameRateError: no rate known; names ``option`` and the recording.
    """
    if given_hz is not None:
        given_hz = float(given_hz)
        if not (math.isfinite(given_hz) and 0 < given_hz <= MAX_FPS_HZ):
            raise ParameterError(option, given_hz, f"a frame rate > 0 and <= {MAX_FPS_HZ:g} "
                                 "frames/s")
        if stated_hz is not None and abs(given_hz / stated_hz - 1.0) > RATE_TOLERANCE:
            if warn is not None:
                warn(f"warning: {option} {given_hz:g} frames/s overrides the {stated_hz:g} "
                     f"frames/s {source} states ({stated_source}); using {given_hz:g}")
        return FrameRate(given_hz, f"{option} (given)", stated_hz)
    if stated_hz is not None:
        return FrameRate(float(stated_hz), stated_source or "the recording", stated_hz)
    if container_hz is not None:
        why = (f"no frame rate known: its container's {container_hz:g} frames/s is a playback "
               "rate, not the camera's, and is not used")
    elif stated_source and stated_source.startswith("none: "):
        why = f"no frame rate known ({stated_source.removeprefix('none: ')})"
    else:
        why = "no frame rate known: the file states none"
    raise MissingFrameRateError(f"{source}: {why}; give the recording's frame rate with "
                                f"{option} (frames/s), e.g. {option} 4500")
