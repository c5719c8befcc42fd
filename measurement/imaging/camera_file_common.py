"""What the camera-file readers share (:mod:`measurement.imaging.mraw`,
:mod:`measurement.imaging.cine`): the error naming file and field, the metadata record, size
and frame-rate checks."""
from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np  # noqa: F401

from abu_model.params import MAX_CAMERA_FPS_HZ


from measurement.imaging.recording_checks import MAX_FRAMES, MAX_PIXELS, RecordingError

#: Largest header text read (a real .cih is ~9 kB, a .cihx ~20 kB).
MAX_HEADER_BYTES = 4 * 2**20
#: Largest image side [px] and frame rate [fps] taken as plausible.
MAX_SIDE_PX = 65535
MAX_FPS = MAX_CAMERA_FPS_HZ
#: Frames unpacked per block (12-bit MRAW) and written per block.
BLOCK_FRAMES = 64

MRAW_SUFFIXES = (".cih", ".cihx", ".mraw")
CINE_SUFFIXES = (".cine",)
CAMERA_FILE_SUFFIXES = MRAW_SUFFIXES + CINE_SUFFIXES


class CameraFileError(RecordingError):
    """A camera file cannot be read: names the file, the field and what was expected.

    Attributes:
        path: the file concerned (header, raw data or CINE file).
        field: the header field or part of the file at fault ('' when the whole file).
    """

    def __init__(self, path: str | os.PathLike, field: str, problem: str):
        self.path = str(path)
        self.field = field
        where = f"'{path}'" + (f", {field}" if field else "")
        super().__init__(f"{where}: {problem}")


@dataclass(frozen=True)
class CameraFileInfo:
    """What a camera file's header says.

    Attributes:
        format: ``"Photron MRAW"`` or ``"Phantom CINE"``.
        fps_hz: frame rate of the saved frames [1/s]; None when the header gives none reliably.
        bit_depth: bits per sample in the file (8, 12 for packed MRAW, 16).
        width_px, height_px, n_frames: frame size and count.
        first_frame_time_s: time of the first saved frame after the trigger [s] (negative
            before it); None without a frame rate.
        trigger_frame: index in the file of the trigger image, None if it was not saved.
        source: the file(s) read, for messages and summaries.
        fps_source: where ``fps_hz`` came from (or why there is none).
        effective_bits: significant bits per sample the camera states (Photron
            ``EffectiveBit Depth``, Phantom ``RealBPP``), None if not stated.
        trigger_time_unix_s: CINE ``TriggerTime`` as seconds since 1970 (UTC), None if unset.
        header: the raw header fields read (text), for reference.
    """

    format: str
    fps_hz: float | None
    bit_depth: int
    width_px: int
    height_px: int
    n_frames: int
    first_frame_time_s: float | None
    trigger_frame: int | None
    source: str
    fps_source: str | None = None
    effective_bits: int | None = None
    trigger_time_unix_s: float | None = None
    header: dict = field(default_factory=dict, compare=False, repr=False)


# --------------------------------------------------------------------------- helpers

_INT = re.compile(r"[+-]?\d{1,18}")
_FLOAT = re.compile(r"[+-]?(\d+(\.\d*)?|\.\d+)([eE][+-]?\d+)?")


def _file_size(p: Path) -> int:
    try:
        if not p.is_file():
            raise CameraFileError(p, "", "does not exist or is not a file")
        return p.stat().st_size
    except OSError as exc:
        raise CameraFileError(p, "", f"cannot be read: {exc}") from None


def _check_frames_fit(p: Path, field_name: str, n: int, h: int, w: int) -> None:
    """The frame and pixel counts must be ones the toolkit holds in memory."""
    if n > MAX_FRAMES:
        raise CameraFileError(p, field_name, f"{n} frames; at most {MAX_FRAMES} are read")
    if n * h * w > MAX_PIXELS:
        raise CameraFileError(p, field_name, f"{n} frames of {w}x{h} px = "
                              f"{n * h * w / 2**30:.1f} Gpixel; at most "
                              f"{MAX_PIXELS / 2**30:.0f} Gpixel are read")


def _check_fps(p: Path, field_name: str, fps: float) -> float:
    if not (math.isfinite(fps) and 0 < fps <= MAX_FPS):
        raise CameraFileError(p, field_name, f"frame rate {fps!r}; expected a finite rate > 0 "
                              f"and <= {MAX_FPS:g} fps")
    return float(fps)


def _trigger_index(first_number: int, n: int, step: int = 1) -> int | None:
    """Index of image number 0 among ``first_number + i * step``, i < n (None if absent)."""
    if first_number > 0 or (-first_number) % step:
        return None
    i = -first_number // step
    return i if i < n else None


def _check_frames_to_write(target: Path, frames, bit_depth: int, depths: tuple[int, ...]
                           ) -> np.ndarray:
    frames = np.asarray(frames)
    if bit_depth not in depths:
        raise CameraFileError(target, "bit_depth", f"{bit_depth!r}; expected one of {depths}")
    want = np.uint8 if bit_depth == 8 else np.uint16
    if frames.ndim != 3 or min(frames.shape) < 1 or frames.dtype != want:
        raise CameraFileError(target, "frames", f"shape {frames.shape} dtype {frames.dtype}; "
                              f"expected (N, H, W) {np.dtype(want)} for {bit_depth}-bit")
    if max(frames.shape[1:]) > MAX_SIDE_PX:
        raise CameraFileError(target, "frames", f"frame size {frames.shape[2]}x"
                              f"{frames.shape[1]} px; at most {MAX_SIDE_PX} px a side")
    if bit_depth == 12 and int(frames.max()) >= 4096:
        raise CameraFileError(target, "frames", f"largest sample {int(frames.max())}; 12-bit "
                              "samples are below 4096")
    return frames
