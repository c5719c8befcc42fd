"""Photron MRAW frames with their CIH / CIHX header: reader and writer (layout in
:mod:`measurement.imaging.camera_files`)."""
from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from abu_model.atomic_io import atomic_open

from measurement.imaging.camera_file_common import (
    BLOCK_FRAMES, CameraFileError, CameraFileInfo, MAX_HEADER_BYTES, MAX_SIDE_PX,
    MRAW_SUFFIXES, _FLOAT, _INT, _check_fps, _check_frames_fit,
    _check_frames_to_write, _file_size, _trigger_index)


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
        "Comment Text": "written by abu-friction measurement.imaging.camera_files",
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


