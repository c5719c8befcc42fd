"""A recording in memory: the (N, H, W) uint8 frames and what is known about them."""
from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np

from measurement.imaging.recording_checks import RecordingError

#: File name endings read as single frames in a folder.
FRAME_SUFFIXES = (".png", ".bmp", ".tif", ".tiff")
TIFF_SUFFIXES = (".tif", ".tiff")
#: Endings tried as video files (anything else unknown is tried as video too, last).
VIDEO_SUFFIXES = (".avi", ".mp4", ".mov", ".mkv", ".m4v", ".mpg", ".mpeg", ".wmv")


@dataclass
class Recording:
    """A recording in memory (or memory-mapped).

    Attributes:
        frames: (N, H, W) uint8 array, C order; frame index first. Pixel (row, col) = (y, x).
        source: human-readable description of where it came from (path and format).
        frame_names: for a folder of frames, the file name of each frame (for messages);
            None for stacks and videos.
        fps_hz, fps_source: frame rate the file states [1/s] and where it was read (camera
            file header, our TIFF metadata, a render's meta.json); None when the file gives
            none (``fps_source`` may then say why). See :mod:`frame_rate`.
        bit_depth: bits per sample in a camera file (before conversion to 8 bits), else None.
        first_frame_time_s: time of the first frame after the camera's trigger [s], if known.
        container_fps_hz: a video container's (playback) rate [1/s]: reported, never used as
            the recording's rate.
        codec: a video container's FourCC (OpenCV ``CAP_PROP_FOURCC``), else None.
    """

    frames: np.ndarray
    source: str
    frame_names: list[str] | None = field(default=None)
    fps_hz: float | None = None
    fps_source: str | None = None
    bit_depth: int | None = None
    first_frame_time_s: float | None = None
    container_fps_hz: float | None = None
    codec: str | None = None

    def __len__(self) -> int:
        return int(self.frames.shape[0])

    @property
    def shape(self) -> tuple[int, int, int]:
        """(N, H, W): number of frames, height and width [px]."""
        return tuple(int(s) for s in self.frames.shape)  # type: ignore[return-value]

    def frame_label(self, index: int) -> str:
        """``frame <index>`` plus its file name when known, for error messages."""
        if self.frame_names is not None and 0 <= index < len(self.frame_names):
            return f"frame {index} ({self.frame_names[index]})"
        return f"frame {index}"


def natural_key(name: str) -> list:
    """Sort key that orders embedded numbers by value: ``img2`` < ``img10``."""
    return [int(tok) if tok.isdigit() else tok.lower() for tok in re.split(r"(\d+)", name)]


def check_stack(frames: np.ndarray, where: str) -> np.ndarray:
    """Check ``frames`` is an (N, H, W) uint8 stack with N >= 1; return it (2-D -> 1 frame).

    Raises:
        RecordingError: naming ``where`` and what was expected.
    """
    if not isinstance(frames, np.ndarray):
        raise RecordingError(f"{where}: expected a numpy array of frames, got {type(frames).__name__}")
    if frames.dtype != np.uint8:
        raise RecordingError(f"{where}: frames have dtype {frames.dtype}; expected 8-bit "
                             "grayscale (uint8)")
    if frames.ndim == 2:
        frames = frames[np.newaxis]
    if frames.ndim != 3:
        hint = " (colour frames? convert to 8-bit grayscale)" if frames.ndim == 4 else ""
        raise RecordingError(f"{where}: frames have shape {frames.shape}; expected (N, H, W)"
                             f"{hint}")
    if frames.shape[0] < 1 or frames.shape[1] < 1 or frames.shape[2] < 1:
        raise RecordingError(f"{where}: empty recording, shape {frames.shape}")
    return frames
