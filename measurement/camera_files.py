"""Read and write the files high-speed cameras save: Photron MRAW (+ CIH / CIHX header) and
Vision Research Phantom CINE (issue 20).

Readers return ``(frames, info)``: ``frames`` an (N, H, W) array of uint8 or uint16 in the
camera's native bit depth (the toolkit's 16-bit -> 8-bit conversion, :mod:`sample_formats`,
follows in :func:`measurement.frames_io.read_recording`), memory-mapped where the layout allows
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
  pixels, rows bottom-up (a positive biHeight, as in a Windows bitmap).

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

Every problem raises :class:`CameraFileError` (a :class:`measurement.frames_io.RecordingError`)
naming the file, the header field and what was expected.
"""
from __future__ import annotations

import math
import os
import re
import struct
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from abu_model.atomic_io import atomic_open

from .frames_io import RecordingError  # frames_io imports this module only inside a function
from .recording_checks import MAX_FRAMES, MAX_PIXELS

#: Largest header text read (a real .cih is ~9 kB, a .cihx ~20 kB).
MAX_HEADER_BYTES = 4 * 2**20
#: Largest image side [px] and frame rate [fps] taken as plausible.
MAX_SIDE_PX = 65535
MAX_FPS = 1e8
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


# --------------------------------------------------------------------------- MRAW + CIH

#: CIH keys read, with their place in a .cihx (XML) header.
CIHX_PATHS = {
    "Record Rate(fps)": "recordInfo/recordRate",
    "Image Width": "imageDataInfo/resolution/width",
    "Image Height": "imageDataInfo/resolution/height",
    "Total Frame": "frameInfo/totalFrame",
    "Original Total Frame": "frameInfo/recordedFrame",
    "Start Frame": "frameInfo/startFrame",
    "Correct Trigger Frame": "frameInfo/correctTriggerFrame",
    "Save Step": "frameInfo/skipFrame",
    "Color Type": "imageDataInfo/colorInfo/type",
    "Color Bit": "imageDataInfo/colorInfo/bit",
    "EffectiveBit Depth": "imageDataInfo/effectiveBit/depth",
    "EffectiveBit Side": "imageDataInfo/effectiveBit/side",
    "File Format": "imageFileInfo/fileFormat",
}


class _Header:
    """Header fields as text, with the name each has in its file (for messages)."""

    def __init__(self, path: Path, values: dict[str, str], labels: dict[str, str]):
        self.path, self.values, self.labels = path, values, labels

    def label(self, key: str) -> str:
        return f"field '{self.labels.get(key, key)}'"

    def text(self, key: str, required: bool = True) -> str | None:
        value = self.values.get(key)
        if value is None and required:
            raise CameraFileError(self.path, self.label(key), "missing from the header")
        return value

    def integer(self, key: str, lo: int, hi: int, required: bool = True,
                expected: str = "") -> int | None:
        raw = self.text(key, required)
        if raw is None:
            return None
        if not _INT.fullmatch(raw.strip()) or not lo <= int(raw) <= hi:
            raise CameraFileError(self.path, self.label(key), f"{raw!r}; expected "
                                  f"{expected or f'an integer from {lo} to {hi}'}")
        return int(raw)

    def number(self, key: str) -> float:
        raw = self.text(key)
        if not _FLOAT.fullmatch(raw.strip()):
            raise CameraFileError(self.path, self.label(key), f"{raw!r}; expected a number")
        return float(raw)


def _read_header_bytes(p: Path) -> bytes:
    size = _file_size(p)
    if size > MAX_HEADER_BYTES:
        raise CameraFileError(p, "", f"{size} bytes; a camera header has at most "
                              f"{MAX_HEADER_BYTES} (is this the header file?)")
    try:
        return p.read_bytes()
    except OSError as exc:
        raise CameraFileError(p, "", f"cannot be read: {exc}") from None


def _parse_cih(p: Path) -> _Header:
    text = _read_header_bytes(p).decode("latin-1")  # keys and numbers are ASCII
    if not text.startswith("#Camera Information Header"):
        raise CameraFileError(p, "first line", f"{text[:40]!r}; expected '#Camera Information "
                              "Header' (a Photron .cih file)")
    values: dict[str, str] = {}
    for line in text.splitlines()[1:]:
        if not line.strip() or line.strip() == "END":
            break  # the camera fields end at the first blank line
        if line.startswith("#") or ":" not in line:
            continue
        key, value = line.split(":", 1)
        values.setdefault(key.strip(), value.strip())
    return _Header(p, values, {})


def _parse_cihx(p: Path) -> _Header:
    data = _read_header_bytes(p)
    start, end = data.find(b"<cih>"), data.rfind(b"</cih>")
    if start < 0 or end < start:
        raise CameraFileError(p, "<cih> element", "not found; expected a Photron .cihx file "
                              "(XML inside <cih>...</cih>)")
    try:  # only the <cih> element is parsed: no DOCTYPE, so no entity expansion
        root = ET.fromstring(data[start:end + len(b"</cih>")].decode("utf-8", "replace"))
    except ET.ParseError as exc:
        raise CameraFileError(p, "<cih> element", f"is not well-formed XML: {exc}") from None
    values, labels = {}, {}
    for key, xml_path in CIHX_PATHS.items():
        labels[key] = f"<{xml_path}>"
        node = root.find(xml_path)
        if node is not None and node.text is not None:
            values[key] = node.text.strip()
    return _Header(p, values, labels)


def mraw_paths(path: str | os.PathLike) -> tuple[Path, Path]:
    """(header, raw data) paths of a Photron recording given its .cih, .cihx or .mraw."""
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix not in MRAW_SUFFIXES:
        raise CameraFileError(p, "", "expected a Photron .cih, .cihx or .mraw file")
    if suffix == ".mraw":
        for s in (".cih", ".cihx", ".CIH", ".CIHX"):
            if p.with_suffix(s).is_file():
                return p.with_suffix(s), p
        raise CameraFileError(p, "", f"no header beside it: expected '{p.with_suffix('.cih')}' "
                              f"or '{p.with_suffix('.cihx')}' (Photron saves one with each "
                              ".mraw; it holds the frame size, count, bit depth and rate)")
    for s in (".mraw", ".MRAW"):
        if p.with_suffix(s).is_file():
            return p, p.with_suffix(s)
    raise CameraFileError(p, "", f"no raw data beside it: expected '{p.with_suffix('.mraw')}'")


def read_mraw(path: str | os.PathLike, *, mmap: bool = True
              ) -> tuple[np.ndarray, CameraFileInfo]:
    """Read a Photron MRAW recording given its .cih, .cihx or .mraw path.

    Returns (frames (N, H, W) uint8 for 8-bit, uint16 for 12- and 16-bit, info). 8- and 16-bit
    frames are memory-mapped unless ``mmap`` is False; 12-bit frames are unpacked in memory.

    Raises:
        CameraFileError: missing header or data file, header field missing or out of range,
            unsupported format / bit depth / colour, data size not the header's.
    """
    hpath, mpath = mraw_paths(path)
    hdr = _parse_cihx(hpath) if hpath.suffix.lower() == ".cihx" else _parse_cih(hpath)

    file_format = hdr.text("File Format")
    if file_format.lower() != "mraw":
        raise CameraFileError(hpath, hdr.label("File Format"), f"{file_format!r}; expected "
                              "'MRaw' (Photron's other formats are TIFF, read as TIFF, or AVI)")
    colour = (hdr.text("Color Type", required=False) or "Mono").strip()
    if colour.lower().startswith("col"):
        raise CameraFileError(hpath, hdr.label("Color Type"), f"{colour!r}: colour frames are "
                              "not read; expected 'Mono' (or 'Raw')")
    bits = hdr.integer("Color Bit", 0, 64, expected="8, 12 or 16 (monochrome)")
    if bits not in (8, 12, 16):
        raise CameraFileError(hpath, hdr.label("Color Bit"), f"{bits} bits per pixel; expected "
                              "8, 12 (packed) or 16 (24 and 48 are colour, not read)")
    width = hdr.integer("Image Width", 1, MAX_SIDE_PX)
    height = hdr.integer("Image Height", 1, MAX_SIDE_PX)
    n = hdr.integer("Total Frame", 1, 2**40)
    _check_frames_fit(hpath, hdr.label("Total Frame"), n, height, width)
    rate = _check_fps(hpath, hdr.label("Record Rate(fps)"), hdr.number("Record Rate(fps)"))
    step = hdr.integer("Save Step", 1, 2**31, required=False) or 1
    start = hdr.integer("Start Frame", -2**40, 2**40, required=False)
    effective = hdr.integer("EffectiveBit Depth", 1, bits, required=False,
                            expected=f"1 to {bits} (the 'Color Bit')")
    side = hdr.text("EffectiveBit Side", required=False)
    if side is not None and side.lower() not in ("lower", "higher"):
        raise CameraFileError(hpath, hdr.label("EffectiveBit Side"), f"{side!r}; expected "
                              "'Lower' or 'Higher'")

    pixels = n * height * width
    if bits == 12 and pixels % 2:
        raise CameraFileError(hpath, hdr.label("Image Width"), f"{n} frames of {width}x{height}"
                              " px is an odd number of 12-bit pixels; packed 12-bit data holds "
                              "pixels in pairs")
    expected_bytes = pixels * bits // 8
    size = _file_size(mpath)
    if size != expected_bytes:
        frame_bytes = height * width * bits // 8
        what = ("is truncated" if size < expected_bytes else "is longer than the header says")
        raise CameraFileError(
            mpath, "", f"{what}: {size} bytes ({size / frame_bytes:.2f} frames); the header "
            f"'{hpath.name}' gives {n} frames of {width}x{height} px at {bits} bits = "
            f"{expected_bytes} bytes")

    try:
        if bits == 12:
            frames = _unpack12(np.memmap(mpath, dtype=np.uint8, mode="r"), (n, height, width))
        else:
            dtype = np.dtype("<u2") if bits == 16 else np.dtype(np.uint8)
            frames = np.memmap(mpath, dtype=dtype, mode="r", shape=(n, height, width))
            if not mmap or not dtype.isnative:
                frames = np.array(frames, dtype=dtype.newbyteorder("="))
    except (OSError, ValueError) as exc:
        raise CameraFileError(mpath, "", f"cannot be read: {exc}") from None

    if step > 1:
        fps, fps_source = None, (
            f"none: {hdr.path.name} {hdr.label('Save Step')} = {step} (every {step}th frame "
            f"saved?) with {hdr.label('Record Rate(fps)')} = {rate:g}; give the rate")
    else:
        fps, fps_source = rate, f"{hpath.suffix.lstrip('.').upper()} header " \
                                f"{hdr.label('Record Rate(fps)')}"
    info = CameraFileInfo(
        format="Photron MRAW", fps_hz=fps, bit_depth=bits, width_px=width, height_px=height,
        n_frames=n, first_frame_time_s=None if start is None else start / rate,
        trigger_frame=None if start is None else _trigger_index(start, n, step),
        source=f"Photron MRAW {mpath} (header {hpath.name})", fps_source=fps_source,
        effective_bits=effective, header=dict(hdr.values))
    return frames, info


def _unpack12(raw: np.ndarray, shape: tuple[int, int, int]) -> np.ndarray:
    """(N, H, W) uint16 from packed 12-bit bytes (2 pixels in 3 bytes, high bits first)."""
    out = np.empty(shape, dtype=np.uint16)
    flat = out.reshape(-1)
    pairs = flat.size // 2
    block = BLOCK_FRAMES * shape[1] * shape[2] // 2 or 1
    for i in range(0, pairs, block):
        j = min(pairs, i + block)
        b = raw[3 * i:3 * j].reshape(-1, 3).astype(np.uint16)
        flat[2 * i:2 * j:2] = (b[:, 0] << 4) | (b[:, 1] >> 4)
        flat[2 * i + 1:2 * j:2] = ((b[:, 1] & 0xF) << 8) | b[:, 2]
    return out


def _pack12(frames: np.ndarray) -> bytes:
    flat = frames.reshape(-1).astype(np.uint16)
    p0, p1 = flat[0::2], flat[1::2]
    out = np.empty((p0.size, 3), dtype=np.uint8)
    out[:, 0] = p0 >> 4
    out[:, 1] = ((p0 & 0xF) << 4) | (p1 >> 8)
    out[:, 2] = p1 & 0xFF
    return out.tobytes()


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


def _fps_text(fps: float) -> str:
    return str(int(fps)) if float(fps).is_integer() else repr(float(fps))


def write_mraw(path_stem: str | os.PathLike, frames: np.ndarray, fps_hz: float,
               bit_depth: int = 8, *, start_frame: int = 0, effective_bits: int | None = None,
               header: str = "cih") -> tuple[Path, Path]:
    """Write a Photron MRAW recording: ``<stem>.mraw`` and its ``<stem>.cih`` (or ``.cihx``).

    Args:
        path_stem: path without suffix (a .cih/.cihx/.mraw suffix is dropped).
        frames: (N, H, W) uint8 for ``bit_depth`` 8, uint16 for 12 (packed, samples < 4096)
            and 16 (little-endian).
        fps_hz: record rate [fps], finite and > 0.
        start_frame: number of the first frame relative to the trigger (0: starts at the
            trigger; -(N-1): ends at it).
        effective_bits: the header's ``EffectiveBit Depth`` (default ``bit_depth``).
        header: ``"cih"`` (text) or ``"cihx"`` (XML).

    Both files are written atomically, the data first. Returns (header path, data path).
    """
    stem = Path(path_stem)
    if stem.suffix.lower() in MRAW_SUFFIXES:
        stem = stem.with_suffix("")
    mpath = stem.with_name(stem.name + ".mraw")
    if header not in ("cih", "cihx"):
        raise CameraFileError(stem, "header", f"{header!r}; expected 'cih' or 'cihx'")
    hpath = stem.with_name(f"{stem.name}.{header}")
    frames = _check_frames_to_write(mpath, frames, bit_depth, (8, 12, 16))
    fps = _check_fps(hpath, "fps_hz", float(fps_hz))
    n, h, w = frames.shape
    if bit_depth == 12 and (n * h * w) % 2:
        raise CameraFileError(mpath, "frames", f"{n * h * w} pixels; packed 12-bit needs an "
                              "even number")
    effective = bit_depth if effective_bits is None else int(effective_bits)
    with atomic_open(mpath, "wb") as handle:
        for i in range(0, n, BLOCK_FRAMES):  # an even count of pixels per block: whole pairs
            block = frames[i:i + BLOCK_FRAMES]
            if bit_depth == 12:
                handle.write(_pack12(block))
            else:
                handle.write(np.ascontiguousarray(block, dtype=block.dtype.newbyteorder("<"))
                             .tobytes())
    trigger_mode = "Start" if start_frame >= 0 else ("End" if start_frame + n - 1 == 0
                                                     else "Center")
    fields = {
        "Date": "", "Time": "", "Camera Type": "abu-friction write_mraw",
        "Record Rate(fps)": _fps_text(fps), "Shutter Speed(s)": f"1/{_fps_text(fps)}",
        "Trigger Mode": trigger_mode, "Original Total Frame": n, "Total Frame": n,
        "Start Frame": int(start_frame), "Correct Trigger Frame": 0, "Save Step": 1,
        "Image Width": w, "Image Height": h, "Color Type": "Mono", "Color Bit": bit_depth,
        "File Format": "MRaw", "EffectiveBit Depth": effective, "EffectiveBit Side": "Lower",
        "Comment Text": "written by abu-friction measurement.camera_files",
    }
    text = _cihx_text(fields) if header == "cihx" else "#Camera Information Header\n" + \
        "".join(f"{k} : {v}\n" for k, v in fields.items()) + "\nEND\n"
    with atomic_open(hpath, "w", encoding="utf-8", newline="\r\n") as handle:
        handle.write(text)
    return hpath, mpath


def _cihx_text(fields: dict) -> str:
    root = ET.Element("cih")
    ET.SubElement(ET.SubElement(root, "fileInfo"), "date").text = "2000/1/1"
    ET.SubElement(ET.SubElement(root, "deviceInfo"), "deviceName").text = fields["Camera Type"]
    ET.SubElement(ET.SubElement(root, "basicInfo"), "comment").text = fields["Comment Text"]
    items = [(xml_path, fields[key]) for key, xml_path in CIHX_PATHS.items()]
    items.append(("recordInfo/shutterSpeed", fields["Record Rate(fps)"]))
    for xml_path, value in items:
        node = root
        for part in xml_path.split("/"):
            node = node.find(part) if node.find(part) is not None else ET.SubElement(node, part)
        node.text = str(value)
    ET.indent(root)
    return ("!!! This file can not be edited. !!!\nCIHX\n<?xml version=\"1.0\" "
            "encoding=\"utf-8\"?>\n" + ET.tostring(root, encoding="unicode") + "\n")


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


def _unpack_at(data: bytes, offset: int, fmt: str):
    return struct.unpack_from(fmt, data, offset)[0]


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
    try:
        with open(p, "rb") as f:
            head = f.read(_CINE_HEADER.size)
            if len(head) < _CINE_HEADER.size:
                raise CameraFileError(p, "CINEFILEHEADER", f"file of {size} bytes; the header "
                                      f"alone has {_CINE_HEADER.size}")
            (kind, header_size, compression, version, _first_movie, total_count, first_no,
             n, off_bih, off_setup, off_table, trigger_time) = _CINE_HEADER.unpack(head)

            def need(what: str, ok: bool, got, expected: str) -> None:
                if not ok:
                    raise CameraFileError(p, what, f"{got!r}; expected {expected}")

            need("CINEFILEHEADER Type", kind == b"CI", kind, "b'CI' (a Phantom .cine file)")
            need("CINEFILEHEADER Headersize", header_size == _CINE_HEADER.size, header_size,
                 str(_CINE_HEADER.size))
            need("CINEFILEHEADER Version", version == 1, version, "1 (64-bit image offsets)")
            need("CINEFILEHEADER Compression", compression == 0, compression,
                 "0, uncompressed grey (1 = JPEG and 2 = raw colour are not read)")
            need("CINEFILEHEADER ImageCount", 1 <= n <= MAX_FRAMES, n,
                 f"1 to {MAX_FRAMES} images")
            need("CINEFILEHEADER OffImageHeader", 44 <= off_bih <= size - _BITMAP_INFO.size,
                 off_bih, f"an offset of the 40-byte BITMAPINFOHEADER inside the {size}-byte "
                 "file")
            need("CINEFILEHEADER OffSetup", 44 <= off_setup <= size - 144, off_setup,
                 f"an offset of the SETUP inside the {size}-byte file")
            need("CINEFILEHEADER OffImageOffsets", 44 <= off_table <= size - 8 * n, off_table,
                 f"an offset of the table of {n} image offsets (8 bytes each) inside the "
                 f"{size}-byte file")

            f.seek(off_bih)
            (bi_size, width, height, _planes, bit_count, bi_compression, _bi_image_size,
             *_rest) = _BITMAP_INFO.unpack(f.read(_BITMAP_INFO.size))
            need("BITMAPINFOHEADER biSize", bi_size >= _BITMAP_INFO.size, bi_size, ">= 40")
            need("BITMAPINFOHEADER biCompression", bi_compression == 0,
                 f"{bi_compression} ({CINE_PACKED.get(bi_compression, 'unknown')})",
                 "0, unpacked 8- or 16-bit samples (save the cine as 16-bit)")
            need("BITMAPINFOHEADER biBitCount", bit_count in (8, 16), bit_count,
                 "8 or 16 (monochrome; 24 and 48 are colour, not read)")
            need("BITMAPINFOHEADER biWidth", 1 <= width <= MAX_SIDE_PX, width,
                 f"1 to {MAX_SIDE_PX} px")
            need("BITMAPINFOHEADER biHeight", 1 <= abs(height) <= MAX_SIDE_PX, height,
                 f"1 to {MAX_SIDE_PX} px (negative: rows stored top-down)")
            bottom_up, height = height > 0, abs(height)
            _check_frames_fit(p, "CINEFILEHEADER ImageCount", n, height, width)

            f.seek(off_setup)
            setup = f.read(min(65535, size - off_setup))  # Length is a uint16
            length = _unpack_at(setup, 142, "<H")
            need("SETUP Mark", setup[140:142] == b"ST", setup[140:142], "b'ST'")
            need("SETUP Length", 144 <= length <= len(setup), length,
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
            need("SETUP RealBPP", real_bpp is None or 0 <= real_bpp <= bit_count, real_bpp,
                 f"0 to {bit_count} (biBitCount)")

            f.seek(off_table)
            offsets = np.frombuffer(f.read(8 * n), dtype="<u8").astype(np.uint64)
    except OSError as exc:
        raise CameraFileError(p, "", f"cannot be read: {exc}") from None

    bps = bit_count // 8
    image_bytes = width * height * bps
    dtype = np.dtype(np.uint8) if bps == 1 else np.dtype("<u2")
    bad = np.flatnonzero(offsets > np.uint64(max(0, size - 8 - image_bytes)))
    if bad.size:
        i = int(bad[0])
        raise CameraFileError(p, f"image offset table (pImage) entry {i}",
                              f"{int(offsets[i])}; expected an offset of image {i} "
                              f"({image_bytes} bytes plus annotation) inside the {size}-byte "
                              "file (truncated?)")
    offsets = offsets.astype(np.int64)
    try:
        raw = np.memmap(p, dtype=np.uint8, mode="r")
    except (OSError, ValueError) as exc:
        raise CameraFileError(p, "", f"cannot be read: {exc}") from None
    ann = raw[offsets[:, None] + np.arange(4)].copy().view("<u4").reshape(n).astype(np.int64)
    bad = np.flatnonzero((ann < 8) | (ann > MAX_ANNOTATION)
                         | (offsets + ann + image_bytes > size))
    if bad.size:
        i = int(bad[0])
        raise CameraFileError(p, f"image {i} AnnotationSize", f"{int(ann[i])}; expected 8 to "
                              f"{MAX_ANNOTATION} bytes, with the {image_bytes}-byte image after "
                              f"it inside the {size}-byte file (truncated?)")
    starts = offsets + ann
    sizes = raw[(starts - 4)[:, None] + np.arange(4)].copy().view("<u4").reshape(n)
    bad = np.flatnonzero(sizes != image_bytes)
    if bad.size:
        i = int(bad[0])
        raise CameraFileError(p, f"image {i} ImageSize", f"{int(sizes[i])}; expected "
                              f"{image_bytes} bytes ({width}x{height} px at {bit_count} bits)")

    stride = int(starts[1] - starts[0]) if n > 1 else image_bytes
    regular = stride >= image_bytes and bool(np.all(np.diff(starts) == stride))
    if regular:
        frames = np.ndarray((n, height, width), dtype=dtype, buffer=raw, offset=int(starts[0]),
                            strides=(stride, width * bps, bps))
        if bottom_up:
            frames = frames[:, ::-1]
        if not mmap or not dtype.isnative:
            frames = np.array(frames, dtype=dtype.newbyteorder("="))
    else:  # images in any order or spacing: copy them one by one
        frames = np.empty((n, height, width), dtype=dtype.newbyteorder("="))
        for i, start in enumerate(starts):
            img = raw[start:start + image_bytes].view(dtype).reshape(height, width)
            frames[i] = img[::-1] if bottom_up else img

    trigger_s = (trigger_time >> 32) + (trigger_time & 0xFFFFFFFF) / 2**32 if trigger_time \
        else None
    header = {"FirstImageNo": first_no, "ImageCount": n, "TotalImageCount": total_count,
              "TriggerTime": trigger_time, "biBitCount": bit_count, "RealBPP": real_bpp,
              fps_field.split()[-1]: rate}
    info = CameraFileInfo(
        format="Phantom CINE", fps_hz=fps, bit_depth=bit_count, width_px=width,
        height_px=height, n_frames=n, first_frame_time_s=first_no / fps,
        trigger_frame=_trigger_index(first_no, n), source=f"Phantom CINE {p}",
        fps_source=f"CINE header '{fps_field}'", effective_bits=real_bpp or None,
        trigger_time_unix_s=trigger_s, header=header)
    return frames, info


def write_cine(path: str | os.PathLike, frames: np.ndarray, fps_hz: float, bit_depth: int = 8,
               *, first_image_no: int = 0, trigger_time_unix_s: float | None = None,
               effective_bits: int | None = None, annotation_bytes: int = 0) -> Path:
    """Write a Phantom .cine file (uncompressed monochrome, rows bottom-up), atomically.

    Args:
        frames: (N, H, W) uint8 for ``bit_depth`` 8, uint16 for 16.
        fps_hz: frame rate, a whole number of fps (the CINE field is an integer).
        first_image_no: number of the first image relative to the trigger (image 0): 0 starts
            at the trigger, -(N-1) ends at it.
        trigger_time_unix_s: wall-clock time of the trigger (seconds since 1970, UTC).
        effective_bits: SETUP ``RealBPP`` (default ``bit_depth``).
        annotation_bytes: extra per-image annotation bytes (zeros) before each image's size.

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
                        ("Description", b"written by abu-friction measurement.camera_files"),
                        ("BlackLevel", 0), ("WhiteLevel", 2**real - 1)):
        offset, fmt = SETUP_FIELDS[name]
        struct.pack_into(fmt, setup, offset, value)

    base = 0.0 if trigger_time_unix_s is None else float(trigger_time_unix_s)
    times = np.maximum(base + (first_image_no + np.arange(n)) / fps, 0.0)
    time64 = (np.floor(times).astype(np.uint64) << np.uint64(32)) + \
        np.round((times % 1.0) * 2**32).clip(0, 2**32 - 1).astype(np.uint64)
    exposure = np.full(n, int(0.5 / fps * 2**32), dtype="<u4")
    tagged = (struct.pack("<IHH", 8 + 8 * n, 1002, 1) + time64.astype("<u8").tobytes()
              + struct.pack("<IHH", 8 + 4 * n, 1003, 0) + exposure.tobytes())

    off_bih = _CINE_HEADER.size
    off_setup = off_bih + _BITMAP_INFO.size
    off_table = off_setup + SETUP_SIZE + len(tagged)
    first_image = off_table + 8 * n
    offsets = first_image + np.arange(n, dtype=np.uint64) * (ann_size + image_bytes)
    trigger64 = 0 if trigger_time_unix_s is None else \
        (int(math.floor(base)) << 32) + min(int(round((base % 1.0) * 2**32)), 2**32 - 1)
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
