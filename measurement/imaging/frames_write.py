"""Write recordings: multi-page TIFF, ``.npy`` stack, folder of frames (each atomically)."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from abu_model.atomic_io import atomic_open

from measurement.imaging.frame_rate import tiff_metadata
from measurement.imaging.recording import FRAME_SUFFIXES, RecordingError, check_stack


def write_multipage_tiff(path: str | os.PathLike, frames: np.ndarray, *,
                         fps_hz: float | None = None,
                         first_frame_time_s: float | None = None) -> Path:
    """Write an (N, H, W) uint8 stack as one multi-page grayscale TIFF, atomically.

    Args:
        fps_hz: frame rate [frames/s], stored in the TIFF's JSON ImageDescription
            (:mod:`measurement.imaging.frame_rate`) for the reader to use; None: none stored.
        first_frame_time_s: time of frame 0 [s], stored beside the rate.

    Returns the path written. Raises :class:`RecordingError` if ``frames`` is not a stack.
    """
    import tifffile

    target = Path(path)
    frames = check_stack(np.asarray(frames), f"frames for '{target}'")
    metadata = tiff_metadata(fps_hz, first_frame_time_s)
    with atomic_open(target, "wb") as handle:
        tifffile.imwrite(handle, frames, photometric="minisblack", contiguous=True,
                         metadata=metadata)
    return target


def write_npy(path: str | os.PathLike, frames: np.ndarray) -> Path:
    """Write an (N, H, W) uint8 stack as a ``.npy`` file, atomically. Returns the path."""
    target = Path(path)
    frames = check_stack(np.asarray(frames), f"frames for '{target}'")
    with atomic_open(target, "wb") as handle:
        np.save(handle, np.ascontiguousarray(frames), allow_pickle=False)
    return target


def write_frame_folder(folder: str | os.PathLike, frames: np.ndarray, *, suffix: str = ".png",
                       prefix: str = "frame") -> Path:
    """Write each frame as ``<prefix><index>.png`` (or .bmp/.tif) in ``folder``, atomically per file.

    Names carry no zero padding on purpose: the reader's natural order must handle them.
    """
    import cv2

    suffix = suffix.lower()
    if suffix not in FRAME_SUFFIXES:
        raise RecordingError(f"frame file type '{suffix}': expected one of {FRAME_SUFFIXES}")
    folder = Path(folder)
    frames = check_stack(np.asarray(frames), f"frames for '{folder}'")
    folder.mkdir(parents=True, exist_ok=True)
    for i, img in enumerate(frames):
        ok, buf = cv2.imencode(suffix, img)
        if not ok:
            raise RecordingError(f"cannot encode frame {i} as {suffix}")
        with atomic_open(folder / f"{prefix}{i}{suffix}", "wb") as handle:
            handle.write(buf.tobytes())
    return folder
