"""Vision Research Phantom CINE files: reader and writer (layout in
:mod:`measurement.imaging.camera_files`)."""
from __future__ import annotations

import math
import os
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from abu_model.atomic_io import atomic_open

from measurement.imaging.camera_file_common import (MAX_SIDE_PX, CameraFileError, CameraFileInfo,
                                                   _check_fps, _check_frames_fit,
                                                   _check_frames_to_write, _file_size,
                                                   _trigger_index)
from measurement.imaging.recording_checks import MAX_FRAMES


# --------------------------------------------------------------------------- CINE

_CINE_HEADER = struct.Struct("<2sHHHiIiIIIIQ")   # CINEFILEHEADER, 44 bytes
_BITMAP_INFO = struct.Struct("<IiiHHIIiiII")      # BITMAPINFOHEADER, 40 bytes
#: SETUP fields read: name -> (offset, struct format). Packed layout (pims, pycine).
SETUP_FIELDS = {"FrameRate16": (0, "<H"), "Mark": (140, "<2s"), "Length": (142, "<H"),
                "ImWidth": (737, "<H"), "ImHeight": (739, "<H"), "FrameRate": (768, "<I"),
                "SoftwareVersion": (800, "<I"), "CFA": (808, "<I"), "RealBPP": (896, "<I"),
                "Description": (1596, "<4096s"), "BlackLevel": (5732, "<i"),
                "WhiteLevel": (5736, "<i")}
#: Size of the SETUP our writer writes (the full structure as of Phantom software 702).
SETUP_SIZE = 7240
#: Largest per-image annotation accepted [bytes].
MAX_ANNOTATION = 2**20
CINE_PACKED = {256: "packed 10-bit (log-encoded, needs Phantom's LUT)",
               1024: "packed 12-bit"}
#: Tagged block of the images' times (TIME64 each: seconds since 1970 in 32.32 fixed point).
TIME_BLOCK = 1002
#: Largest departure of an image's time from an evenly spaced time base [frame intervals]: the
#: analysis takes frame i at t0 + i / fps, so a dropped frame (a gap of 2 intervals) or an
#: irregular trigger would put theta off by omega * dt and its second difference far more.
TIME_BASE_TOLERANCE = 0.05
#: ... but never below this [s]: time stamps kept to a 1 us camera clock differ by up to 2 us
#: from their true spacing (at 300,000 frames/s, 0.6 of an interval; a dropped frame is 1).
TIME_STAMP_SLACK_S = 2e-6


def _unpack_at(data: bytes, offset: int, fmt: str):
    return struct.unpack_from(fmt, data, offset)[0]


def _need(p: Path, what: str, ok: bool, got, expected: str) -> None:
    """Raise the CameraFileError naming ``what`` unless ``ok``."""
    if not ok:
        raise CameraFileError(p, what, f"{got!r}; expected {expected}")


@dataclass
class _CineLayout:
    """What the headers of a CINE file say (sizes in px, offsets in bytes)."""

    n: int
    first_no: int
    total_count: int
    trigger_time: int
    width: int
    height: int
    bottom_up: bool
    bit_count: int
    fps: float
    fps_field: str
    rate: float
    real_bpp: int | None
    offsets: np.ndarray


def _file_header(p: Path, size: int, head: bytes) -> tuple:
    """The CINEFILEHEADER's fields, each checked against the file."""
    if len(head) < _CINE_HEADER.size:
        raise CameraFileError(p, "CINEFILEHEADER", f"file of {size} bytes; the header "
                              f"alone has {_CINE_HEADER.size}")
    (kind, header_size, compression, version, _first_movie, total_count, first_no,
     n, off_bih, off_setup, off_table, trigger_time) = _CINE_HEADER.unpack(head)
    _need(p, "CINEFILEHEADER Type", kind == b"CI", kind, "b'CI' (a Phantom .cine file)")
    _need(p, "CINEFILEHEADER Headersize", header_size == _CINE_HEADER.size, header_size,
          str(_CINE_HEADER.size))
    _need(p, "CINEFILEHEADER Version", version == 1, version, "1 (64-bit image offsets)")
    _need(p, "CINEFILEHEADER Compression", compression == 0, compression,
          "0, uncompressed grey (1 = JPEG and 2 = raw colour are not read)")
    _need(p, "CINEFILEHEADER ImageCount", 1 <= n <= MAX_FRAMES, n, f"1 to {MAX_FRAMES} images")
    _need(p, "CINEFILEHEADER OffImageHeader", 44 <= off_bih <= size - _BITMAP_INFO.size,
          off_bih, f"an offset of the 40-byte BITMAPINFOHEADER inside the {size}-byte file")
    _need(p, "CINEFILEHEADER OffSetup", 44 <= off_setup <= size - 144, off_setup,
          f"an offset of the SETUP inside the {size}-byte file")
    _need(p, "CINEFILEHEADER OffImageOffsets", 44 <= off_table <= size - 8 * n, off_table,
          f"an offset of the table of {n} image offsets (8 bytes each) inside the "
          f"{size}-byte file")
    return total_count, first_no, n, off_bih, off_setup, off_table, trigger_time


def _bitmap_header(p: Path, data: bytes, n: int) -> tuple[int, int, bool, int]:
    """(width, height, bottom_up, bit count) from the BITMAPINFOHEADER."""
    (bi_size, width, height, _planes, bit_count, bi_compression, _bi_image_size,
     *_rest) = _BITMAP_INFO.unpack(data)
    _need(p, "BITMAPINFOHEADER biSize", bi_size >= _BITMAP_INFO.size, bi_size, ">= 40")
    _need(p, "BITMAPINFOHEADER biCompression", bi_compression == 0,
          f"{bi_compression} ({CINE_PACKED.get(bi_compression, 'unknown')})",
          "0, unpacked 8- or 16-bit samples (save the cine as 16-bit)")
    _need(p, "BITMAPINFOHEADER biBitCount", bit_count in (8, 16), bit_count,
          "8 or 16 (monochrome; 24 and 48 are colour, not read)")
    _need(p, "BITMAPINFOHEADER biWidth", 1 <= width <= MAX_SIDE_PX, width,
          f"1 to {MAX_SIDE_PX} px")
    _need(p, "BITMAPINFOHEADER biHeight", 1 <= abs(height) <= MAX_SIDE_PX, height,
          f"1 to {MAX_SIDE_PX} px (negative: rows stored top-down)")
    _check_frames_fit(p, "CINEFILEHEADER ImageCount", n, abs(height), width)
    return width, abs(height), height > 0, bit_count


def _setup(p: Path, setup: bytes, bit_count: int) -> tuple[float, str, float, int | None]:
    """(frame rate [frames/s], the field it came from, its raw value, RealBPP) from SETUP."""
    length = _unpack_at(setup, 142, "<H")
    _need(p, "SETUP Mark", setup[140:142] == b"ST", setup[140:142], "b'ST'")
    _need(p, "SETUP Length", 144 <= length <= len(setup), length,
          f"the SETUP's size, 144 to {len(setup)} bytes (the rest of the file)")
    setup = setup[:length]

    def setup_field(name: str):
        offset, fmt = SETUP_FIELDS[name]
        end = offset + struct.calcsize(fmt)
        return _unpack_at(setup, offset, fmt) if end <= length else None

    fps_field = "SETUP FrameRate"
    rate = setup_field("FrameRate")
    if not rate:
        fps_field, rate = "SETUP FrameRate16", setup_field("FrameRate16")
    fps = _check_fps(p, fps_field, float(rate))
    real_bpp = setup_field("RealBPP")
    _need(p, "SETUP RealBPP", real_bpp is None or 0 <= real_bpp <= bit_count, real_bpp,
          f"0 to {bit_count} (biBitCount)")
    return fps, fps_field, rate, real_bpp


def _image_times(blocks: bytes, n: int) -> np.ndarray | None:
    """The images' times [s] after the first from the tagged blocks (None without a
    complete time block)."""
    pos = 0
    while pos + 8 <= len(blocks):
        block_size, kind = struct.unpack_from("<IH", blocks, pos)
        if block_size < 8 or pos + block_size > len(blocks):
            return None      # not tagged blocks as documented: nothing to check
        if kind == TIME_BLOCK and block_size >= 8 + 8 * n:
            t64 = np.frombuffer(blocks, dtype="<u8", count=n, offset=pos + 8).astype(np.int64)
            return (t64 - t64[0]) / 2**32    # exact differences (a float of 1.7e9 s is not)
        pos += block_size
    return None


def _check_image_times(p: Path, blocks: bytes, n: int, fps: float) -> None:
    """Refuse images that are not evenly spaced at 1 / fps (dropped or repeated frames, an
    irregular trigger): every later stage assumes frame i at t0 + i / fps."""
    t = _image_times(blocks, n)
    if t is None or n < 2 or not t.any():
        return          # no time block, or one left zero (times not recorded): nothing to check
    dt = np.diff(t) * fps    # intervals [frame intervals]
    bad = np.flatnonzero(np.abs(dt - 1.0) > max(TIME_BASE_TOLERANCE, TIME_STAMP_SLACK_S * fps))
    if bad.size:
        i = int(bad[0])
        raise CameraFileError(p, f"image times (tagged block {TIME_BLOCK})",
                              f"images {i} and {i + 1} {dt[i] / fps * 1e6:.1f} us apart "
                              f"({dt[i]:.3g} frame intervals; {bad.size} uneven intervals); "
                              f"expected evenly spaced images at the SETUP's {fps:g} frames/s "
                              "(dropped frames or an irregular trigger cannot be measured)")


def _read_layout(p: Path, size: int) -> _CineLayout:
    """Every header of the file, checked before any image is touched."""
    try:
        with open(p, "rb") as f:
            total_count, first_no, n, off_bih, off_setup, off_table, trigger_time = \
                _file_header(p, size, f.read(_CINE_HEADER.size))
            f.seek(off_bih)
            width, height, bottom_up, bit_count = _bitmap_header(
                p, f.read(_BITMAP_INFO.size), n)
            f.seek(off_setup)
            setup = f.read(min(65535, size - off_setup))   # Length is a uint16
            fps, fps_field, rate, real_bpp = _setup(p, setup, bit_count)
            setup_end = off_setup + _unpack_at(setup, 142, "<H")
            if off_table > setup_end:   # tagged blocks lie between the SETUP and the table
                f.seek(setup_end)
                _check_image_times(p, f.read(off_table - setup_end), n, fps)
            f.seek(off_table)
            offsets = np.frombuffer(f.read(8 * n), dtype="<u8").astype(np.uint64)
    except OSError as exc:
        raise CameraFileError(p, "", f"cannot be read: {exc}") from None
    return _CineLayout(n, first_no, total_count, trigger_time, width, height, bottom_up,
                       bit_count, fps, fps_field, rate, real_bpp, offsets)


def _image_starts(p: Path, size: int, raw: np.ndarray, lay: _CineLayout,
                  image_bytes: int) -> np.ndarray:
    """File offsets of the images' pixels, past each annotation; every size checked."""
    offsets = lay.offsets
    bad = np.flatnonzero(offsets > np.uint64(max(0, size - 8 - image_bytes)))
    if bad.size:
        i = int(bad[0])
        raise CameraFileError(p, f"image offset table (pImage) entry {i}",
                              f"{int(offsets[i])}; expected an offset of image {i} "
                              f"({image_bytes} bytes plus annotation) inside the {size}-byte "
                              "file (truncated?)")
    offsets = offsets.astype(np.int64)
    ann = raw[offsets[:, None] + np.arange(4)].copy().view("<u4").reshape(lay.n)
    ann = ann.astype(np.int64)
    bad = np.flatnonzero((ann < 8) | (ann > MAX_ANNOTATION)
                         | (offsets + ann + image_bytes > size))
    if bad.size:
        i = int(bad[0])
        raise CameraFileError(p, f"image {i} AnnotationSize", f"{int(ann[i])}; expected 8 to "
                              f"{MAX_ANNOTATION} bytes, with the {image_bytes}-byte image after "
                              f"it inside the {size}-byte file (truncated?)")
    starts = offsets + ann
    sizes = raw[(starts - 4)[:, None] + np.arange(4)].copy().view("<u4").reshape(lay.n)
    bad = np.flatnonzero(sizes != image_bytes)
    if bad.size:
        i = int(bad[0])
        raise CameraFileError(p, f"image {i} ImageSize", f"{int(sizes[i])}; expected "
                              f"{image_bytes} bytes ({lay.width}x{lay.height} px at "
                              f"{lay.bit_count} bits)")
    return starts


def _frames(raw: np.ndarray, starts: np.ndarray, lay: _CineLayout, mmap: bool) -> np.ndarray:
    """(N, H, W) images, top row first: a view where they lie at a constant stride."""
    n, height, width = lay.n, lay.height, lay.width
    bps = lay.bit_count // 8
    image_bytes = width * height * bps
    dtype = np.dtype(np.uint8) if bps == 1 else np.dtype("<u2")
    stride = int(starts[1] - starts[0]) if n > 1 else image_bytes
    if stride >= image_bytes and bool(np.all(np.diff(starts) == stride)):
        frames = np.ndarray((n, height, width), dtype=dtype, buffer=raw, offset=int(starts[0]),
                            strides=(stride, width * bps, bps))
        if lay.bottom_up:
            frames = frames[:, ::-1]
        if not mmap or not dtype.isnative:
            frames = np.array(frames, dtype=dtype.newbyteorder("="))
        return frames
    frames = np.empty((n, height, width), dtype=dtype.newbyteorder("="))
    for i, start in enumerate(starts):  # images in any order or spacing: copy one by one
        img = raw[start:start + image_bytes].view(dtype).reshape(height, width)
        frames[i] = img[::-1] if lay.bottom_up else img
    return frames


def _info(p: Path, lay: _CineLayout) -> CameraFileInfo:
    t = lay.trigger_time
    trigger_s = (t >> 32) + (t & 0xFFFFFFFF) / 2**32 if t else None
    header = {"FirstImageNo": lay.first_no, "ImageCount": lay.n,
              "TotalImageCount": lay.total_count, "TriggerTime": t,
              "biBitCount": lay.bit_count, "RealBPP": lay.real_bpp,
              lay.fps_field.split()[-1]: lay.rate}
    return CameraFileInfo(
        format="Phantom CINE", fps_hz=lay.fps, bit_depth=lay.bit_count, width_px=lay.width,
        height_px=lay.height, n_frames=lay.n, first_frame_time_s=lay.first_no / lay.fps,
        trigger_frame=_trigger_index(lay.first_no, lay.n), source=f"Phantom CINE {p}",
        fps_source=f"CINE header '{lay.fps_field}'", effective_bits=lay.real_bpp or None,
        trigger_time_unix_s=trigger_s, header=header)


def read_cine(path: str | os.PathLike, *, mmap: bool = True
              ) -> tuple[np.ndarray, CameraFileInfo]:
    """Read a Phantom .cine file: 8- or 16-bit monochrome, uncompressed.

    Returns (frames (N, H, W) uint8 or uint16, top row first, info). Images at a constant
    stride are memory-mapped (a view: rows are stored bottom-up) unless ``mmap`` is False.

    Raises:
        CameraFileError: not a CINE file, a header field out of range, colour / compressed /
            packed images, an image offset or size past the end of the file.
    """
    p = Path(path)
    size = _file_size(p)
    lay = _read_layout(p, size)
    image_bytes = lay.width * lay.height * (lay.bit_count // 8)
    try:
        raw = np.memmap(p, dtype=np.uint8, mode="r")
    except (OSError, ValueError) as exc:
        raise CameraFileError(p, "", f"cannot be read: {exc}") from None
    starts = _image_starts(p, size, raw, lay, image_bytes)
    return _frames(raw, starts, lay, mmap), _info(p, lay)


def write_cine(path: str | os.PathLike, frames: np.ndarray, fps_hz: float, bit_depth: int = 8,
               *, first_image_no: int = 0, trigger_time_unix_s: float | None = None,
               effective_bits: int | None = None, annotation_bytes: int = 0,
               image_times_s: np.ndarray | None = None) -> Path:
    """Write a Phantom .cine file (uncompressed monochrome, rows bottom-up), atomically.

    Args:
        frames: (N, H, W) uint8 for ``bit_depth`` 8, uint16 for 16.
        fps_hz: frame rate, a whole number of fps (the CINE field is an integer).
        first_image_no: number of the first image relative to the trigger (image 0): 0 starts
            at the trigger, -(N-1) ends at it.
        trigger_time_unix_s: wall-clock time of the trigger (seconds since 1970, UTC).
        effective_bits: SETUP ``RealBPP`` (default ``bit_depth``).
        annotation_bytes: extra per-image annotation bytes (zeros) before each image's size.
        image_times_s: the images' times [s since 1970] in the time block (default: evenly
            spaced at ``fps_hz`` from the trigger); other times record dropped frames or jitter.

    Also writes the tagged blocks of image times (1002) and exposures (1003).
    """
    target = Path(path)
    frames = _check_frames_to_write(target, frames, bit_depth, (8, 16))
    fps = _check_fps(target, "fps_hz", float(fps_hz))
    if not fps.is_integer() or fps > 2**32 - 1:
        raise CameraFileError(target, "fps_hz", f"{fps_hz!r}; a CINE file stores a whole "
                              "number of fps")
    n, h, w = frames.shape
    if not -2**31 <= int(first_image_no) < 2**31:
        raise CameraFileError(target, "first_image_no", f"{first_image_no!r}; expected a 32-bit "
                              "integer")
    if trigger_time_unix_s is not None and not 0 <= float(trigger_time_unix_s) < 2**32:
        raise CameraFileError(target, "trigger_time_unix_s", f"{trigger_time_unix_s!r}; "
                              "expected seconds since 1970, 0 to 2**32")
    real = bit_depth if effective_bits is None else int(effective_bits)
    ann_size = 8 + int(annotation_bytes)
    image_bytes = h * w * (bit_depth // 8)

    setup = bytearray(SETUP_SIZE)
    for name, value in (("FrameRate16", min(int(fps), 65535)), ("Mark", b"ST"),
                        ("Length", SETUP_SIZE), ("ImWidth", min(w, 65535)),
                        ("ImHeight", min(h, 65535)), ("FrameRate", int(fps)),
                        ("SoftwareVersion", 702), ("CFA", 0), ("RealBPP", real),
                        ("Description", b"written by abu-friction measurement.imaging.camera_files"),
                        ("BlackLevel", 0), ("WhiteLevel", 2**real - 1)):
        offset, fmt = SETUP_FIELDS[name]
        struct.pack_into(fmt, setup, offset, value)

    base = 0.0 if trigger_time_unix_s is None else float(trigger_time_unix_s)
    base64 = (int(math.floor(base)) << 32) + min(int(round((base % 1.0) * 2**32)), 2**32 - 1)
    rel_s = (first_image_no + np.arange(n)) / fps if image_times_s is None else \
        np.asarray(image_times_s, dtype=float).reshape(n) - base
    # 32.32 fixed point, added in integers (seconds since 1970 in a float lose 0.2 us)
    rel64 = np.round(rel_s * 2**32).astype(np.int64)
    if trigger_time_unix_s is None:   # no clock: times from 0 (none before 1970, none equal)
        base64 = max(0, -int(rel64.min()))
    time64 = np.maximum(base64 + rel64, 0).astype(np.uint64)
    exposure = np.full(n, int(0.5 / fps * 2**32), dtype="<u4")
    tagged = (struct.pack("<IHH", 8 + 8 * n, 1002, 1) + time64.astype("<u8").tobytes()
              + struct.pack("<IHH", 8 + 4 * n, 1003, 0) + exposure.tobytes())

    off_bih = _CINE_HEADER.size
    off_setup = off_bih + _BITMAP_INFO.size
    off_table = off_setup + SETUP_SIZE + len(tagged)
    first_image = off_table + 8 * n
    offsets = first_image + np.arange(n, dtype=np.uint64) * (ann_size + image_bytes)
    trigger64 = 0 if trigger_time_unix_s is None else base64   # 0: unknown
    head = _CINE_HEADER.pack(b"CI", _CINE_HEADER.size, 0, 1, int(first_image_no), n,
                             int(first_image_no), n, off_bih, off_setup, off_table, trigger64)
    bih = _BITMAP_INFO.pack(_BITMAP_INFO.size, w, h, 1, bit_depth, 0, image_bytes, 0, 0, 0, 0)
    annotation = struct.pack("<I", ann_size) + bytes(int(annotation_bytes)) + \
        struct.pack("<I", image_bytes)
    le = np.dtype(frames.dtype).newbyteorder("<")
    with atomic_open(target, "wb") as handle:
        handle.write(head + bih + bytes(setup) + tagged + offsets.astype("<u8").tobytes())
        for img in frames:
            handle.write(annotation)
            handle.write(np.ascontiguousarray(img[::-1], dtype=le).tobytes())
    return target
