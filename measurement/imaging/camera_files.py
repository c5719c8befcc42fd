"""Read and write the files high-speed cameras save: Photron MRAW (+ CIH / CIHX header) and
Vision Research Phantom CINE (issue 20).

Readers return ``(frames, info)``: ``frames`` an (N, H, W) array of uint8 or uint16 in the
camera's native bit depth (the toolkit's 16-bit -> 8-bit conversion, :mod:`sample_formats`,
follows in :func:`measurement.imaging.frames_io.read_recording`), memory-mapped where the layout allows
(8- and 16-bit MRAW; CINE whose images lie at a constant stride), and ``info`` a
:class:`CameraFileInfo` with the frame rate, bit depth, size, frame count and trigger.

Layouts (checked against pyMRAW 0.33 and pims 0.7 ``pims/cine.py``, see the tests):

* **MRAW**: frames back to back, no header, row-major, top row first. 8-bit: one byte per
  pixel; 16-bit: little-endian words (as Photron's Windows software writes them and pyMRAW
  maps them); 12-bit: two pixels in three bytes, most significant bits first
  (``p0 = b0 << 4 | b1 >> 4``, ``p1 = (b1 & 0xF) << 8 | b2``), the stream running on across frame
  boundaries. The ``.cih`` beside it is ``Key : Value`` text; the ``.cihx`` holds the same
  fields as XML (``<cih>...</cih>``, after a short binary preamble).
* **CINE** (all little-endian): CINEFILEHEADER (44 bytes: ``"CI"``, header size, compression,
  version, first movie image, total image count, FirstImageNo, ImageCount, offsets of the
  BITMAPINFOHEADER, the SETUP and the image offset table, TriggerTime as 32.32 fixed-point
  seconds since 1970); BITMAPINFOHEADER (40 bytes, Windows layout); SETUP (packed; ``Mark``
  ``"ST"`` at byte 140, ``Length`` at 142, ``FrameRate16`` at 0, ``FrameRate`` (uint32) at 768,
  ``RealBPP`` at 896); the pImage table (ImageCount int64 file offsets); each image: an
  annotation (uint32 AnnotationSize, AnnotationSize - 8 bytes, uint32 ImageSize), then the
  pixels, rows bottom-up (a positive biHeight, as in a Windows bitmap). Between the SETUP
  and the pImage table: tagged blocks (uint32 BlockSize, uint16 Type, uint16 reserved, data);
  Type 1002 holds each image's time (TIME64, 32.32 fixed point). Images not evenly spaced at
  the SETUP's rate (a dropped frame, a jittered trigger) are refused: every later stage takes
  frame i at t0 + i / fps. A time block left zero is read as no times.

Times: image number 0 is the trigger. ``first_frame_time_s`` is the time of the file's first
frame after the trigger (negative when frames before the trigger were kept): CINE
``FirstImageNo / FrameRate``, MRAW ``Start Frame / Record Rate(fps)``. ``trigger_frame`` is the
index in the file of the trigger image, None when the trigger is outside the saved frames.

Not read (refused with a message saying so): colour (interpolated RGB, Photron ``Color Type``
colour, CINE 24/48-bit, CINE compression 1 = JPEG, 2 = raw colour), CINE packed 10-bit
(biCompression 256, log-encoded through Phantom's LUT) and packed 12-bit (biCompression 1024):
save as 16-bit from Phantom's software instead. A Photron ``Save Step`` (``skipFrame``) above 1
gives no frame rate (``fps_hz`` None, ``fps_source`` says why): the two public sample files with
one do not agree on what it means.

Why our own reader: the layouts are a few pages, and the readers must refuse a cut or damaged
file with a message naming the file and the field (the toolkit's rule) and check every header
value before allocating. pyMRAW (GPL-3 in its source headers, MIT in its 0.33 package) pulls
numba + llvmlite (~100 MB) and nose, and reads whatever ``Total Frame`` says without checking
the file size. pims (BSD) would fit the licence and its dependencies are light (imageio,
slicerator), but its CINE reader reads one frame at a time through ``struct`` (slow for 3072
frames), has no writer, needs the optional tagged blocks (a file without them fails with a
``TypeError``) and raises bare ``ValueError``/``struct.error`` on damaged files. Both are used
in the tests as independent cross-checks only, never at run time.

Every problem raises :class:`CameraFileError` (a :class:`measurement.imaging.frames_io.RecordingError`)
naming the file, the header field and what was expected.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from measurement.imaging.camera_file_common import (  # noqa: F401  (the public names)
    CAMERA_FILE_SUFFIXES, CINE_SUFFIXES, MRAW_SUFFIXES, CameraFileError, CameraFileInfo)
from measurement.imaging.cine import read_cine, write_cine  # noqa: F401
from measurement.imaging.mraw import mraw_paths, read_mraw, write_mraw  # noqa: F401


def read_camera_file(path: str | os.PathLike, *, mmap: bool = True
                     ) -> tuple[np.ndarray, CameraFileInfo]:
    """Read a Photron MRAW (given its .cih, .cihx or .mraw) or a Phantom .cine file."""
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix in MRAW_SUFFIXES:
        return read_mraw(p, mmap=mmap)
    if suffix in CINE_SUFFIXES:
        return read_cine(p, mmap=mmap)
    raise CameraFileError(p, "", f"unknown camera file type '{p.suffix}'; expected one of "
                          f"{', '.join(CAMERA_FILE_SUFFIXES)}")
