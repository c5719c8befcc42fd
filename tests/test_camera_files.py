"""Photron MRAW/CIH/CIHX and Phantom CINE files (issue 20): round trips, cross-checks, errors.

Each layout is checked three ways:

* our writer -> our reader, frame for frame, with the metadata (rate, bit depth, trigger);
* against a second implementation written here from the documented layouts (a reader and a
  writer that share no code with :mod:`measurement.imaging.camera_files`: 12-bit pairs as one
  big-endian 24-bit word, CINE fields unpacked by name at their offsets, images at irregular
  offsets, a short SETUP);
* against the independent libraries where installed: pyMRAW (Photron; not in the test extras:
  it pulls numba) and pims (``pims.Cine``; in the test extras).

Real Photron files (pyMRAW's sample data, not shipped here) are read when the folder holding
them is given in ``ABU_PHOTRON_SAMPLES``.
"""
from __future__ import annotations

import os
import struct
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from abu_model.errors import AbuError
from measurement.imaging.camera_files import (CameraFileError, CameraFileInfo, read_camera_file,
                                      read_cine, read_mraw, write_cine, write_mraw)
from measurement.imaging.frames_io import RecordingError, read_recording

SETTINGS = dict(deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.function_scoped_fixture,
                                       HealthCheck.too_slow])
N, H, W = 6, 10, 14
TOP = {8: 255, 12: 4095, 16: 65535}


def _frames(bits: int, n: int = N, h: int = H, w: int = W, seed: int = 1) -> np.ndarray:
    """Random frames with each frame's index in pixel (0, 0) and a row ramp in column 0 (a
    flipped row order or a swapped frame cannot go unnoticed)."""
    rng = np.random.default_rng(seed + bits)
    dtype = np.uint8 if bits == 8 else np.uint16
    frames = rng.integers(0, TOP[bits] + 1, size=(n, h, w)).astype(dtype)
    frames[:, :, 0] = np.arange(h, dtype=dtype)[None, :]
    frames[:, 0, 0] = np.arange(n, dtype=dtype) + 100
    frames[0, 0, 1] = TOP[bits]   # the full range is used
    return frames


# ------------------------------------------------------------------ independent reference
def _ref_parse_cih(path: Path) -> dict[str, str]:
    out = {}
    for line in path.read_text(encoding="latin-1").splitlines():
        if " : " in line:
            k, v = line.split(" : ", 1)
            out.setdefault(k, v.strip())
    return out


def _ref_read_mraw(cih: Path) -> np.ndarray:
    """Photron MRAW as documented: 12-bit = a big-endian 24-bit word per pixel pair."""
    hdr = _ref_parse_cih(cih)
    n, h, w = int(hdr["Total Frame"]), int(hdr["Image Height"]), int(hdr["Image Width"])
    bits = int(hdr["Color Bit"])
    data = cih.with_suffix(".mraw").read_bytes()
    if bits == 8:
        return np.frombuffer(data, np.uint8).reshape(n, h, w)
    if bits == 16:
        return np.frombuffer(data, "<u2").astype(np.uint16).reshape(n, h, w)
    b = np.frombuffer(data, np.uint8).reshape(-1, 3).astype(np.uint32)
    word = (b[:, 0] << 16) | (b[:, 1] << 8) | b[:, 2]
    pixels = np.stack([word >> 12, word & 0xFFF], axis=1)
    return pixels.reshape(n, h, w).astype(np.uint16)


def _ref_write_mraw(stem: Path, frames: np.ndarray, fps: float, bits: int,
                    start: int = 0) -> Path:
    n, h, w = frames.shape
    if bits == 12:
        p = frames.reshape(-1, 2).astype(np.uint32)
        word = (p[:, 0] << 12) | p[:, 1]
        data = np.stack([word >> 16, (word >> 8) & 0xFF, word & 0xFF], axis=1).astype(np.uint8)
        raw = data.tobytes()
    else:
        raw = frames.astype("<u2" if bits == 16 else np.uint8).tobytes()
    stem.with_suffix(".mraw").write_bytes(raw)
    cih = stem.with_suffix(".cih")
    cih.write_text("#Camera Information Header\n"
                   f"Record Rate(fps) : {fps:g}\nTrigger Mode : Start\nTotal Frame : {n}\n"
                   f"Start Frame : {start}\nImage Width : {w}\nImage Height : {h}\n"
                   f"Color Type : Mono\nColor Bit : {bits}\nFile Format : MRaw\n"
                   f"EffectiveBit Depth : {bits}\nEffectiveBit Side : Lower\n\n"
                   "#Some Trailing Section\nImage Width : 1\n")
    return cih


def _ref_read_cine(path: Path) -> tuple[np.ndarray, dict]:
    data = path.read_bytes()
    u = lambda fmt, off: struct.unpack_from("<" + fmt, data, off)[0]  # noqa: E731
    n, off_bih, off_setup, off_table = u("I", 20), u("I", 24), u("I", 28), u("I", 32)
    w, h, bits = u("i", off_bih + 4), u("i", off_bih + 8), u("H", off_bih + 14)
    meta = {"first_no": u("i", 16), "fps": u("I", off_setup + 768),
            "trigger": u("Q", 36), "real_bpp": u("I", off_setup + 896)}
    dtype = np.uint8 if bits == 8 else np.dtype("<u2")
    out = []
    for i in range(n):
        start = u("Q", off_table + 8 * i)
        ann = u("I", start)
        size = u("I", start + ann - 4)
        img = np.frombuffer(data, dtype, count=w * h, offset=start + ann).reshape(h, w)
        assert size == img.nbytes
        out.append(np.flipud(img))
    return np.stack(out).astype(np.uint8 if bits == 8 else np.uint16), meta


def _ref_write_cine(path: Path, frames: np.ndarray, fps: int, first_no: int = 0,
                    setup_length: int = 1024, shuffle: bool = True) -> Path:
    """A CINE with a short SETUP, both tagged blocks, and images in reverse file order with
    gaps and annotations of differing sizes (the reader's non-memory-mapped path)."""
    n, h, w = frames.shape
    bits = 8 if frames.dtype == np.uint8 else 16
    setup = bytearray(setup_length)
    struct.pack_into("<H", setup, 0, min(fps, 65535))
    setup[140:142] = b"ST"
    struct.pack_into("<H", setup, 142, setup_length)
    struct.pack_into("<I", setup, 768, fps)
    struct.pack_into("<I", setup, 896, bits)
    if setup_length >= 804:
        struct.pack_into("<I", setup, 800, 702)   # SoftwareVersion: pims drops later fields
    tagged = struct.pack("<IHH", 8 + 8 * n, 1002, 1) + bytes(8 * n) + \
        struct.pack("<IHH", 8 + 4 * n, 1003, 0) + bytes(4 * n)
    off_setup = 44 + 40
    off_table = off_setup + setup_length + len(tagged)
    pos = off_table + 8 * n + 5   # a gap before the first image
    blobs, offsets = {}, [0] * n
    order = list(range(n))[::-1] if shuffle else list(range(n))
    for k, i in enumerate(order):
        extra = 4 * (k % 3)
        img = np.flipud(frames[i]).astype("<u2" if bits == 16 else np.uint8).tobytes()
        blobs[pos] = struct.pack("<I", 8 + extra) + bytes(extra) + struct.pack("<I", len(img)) \
            + img + bytes(k)   # trailing gap of k bytes
        offsets[i] = pos
        pos += len(blobs[pos])
    head = struct.pack("<2sHHHiIiIIIIQ", b"CI", 44, 0, 1, first_no, n, first_no, n, 44,
                       off_setup, off_table, 0)
    bih = struct.pack("<IiiHHIIiiII", 40, w, h, 1, bits, 0, w * h * bits // 8, 0, 0, 0, 0)
    body = head + bih + bytes(setup) + tagged + struct.pack(f"<{n}Q", *offsets) + bytes(5)
    body += b"".join(blobs[k] for k in sorted(blobs))
    path.write_bytes(body)
    return path


# ------------------------------------------------------------------ MRAW round trips
@pytest.mark.parametrize("header", ["cih", "cihx"])
@pytest.mark.parametrize("bits", [8, 12, 16])
def test_mraw_round_trip_and_metadata(tmp_path, bits, header):
    frames = _frames(bits)
    hpath, mpath = write_mraw(tmp_path / "rec", frames, 4500, bits, start_frame=-2,
                              effective_bits=min(bits, 12), header=header)
    assert hpath.name == f"rec.{header}" and mpath.name == "rec.mraw"
    assert mpath.stat().st_size == N * H * W * bits // 8
    for given_path in (hpath, mpath):  # either file names the recording
        got, info = read_mraw(given_path)
        assert got.dtype == (np.uint8 if bits == 8 else np.uint16)
        np.testing.assert_array_equal(got, frames)
    assert isinstance(info, CameraFileInfo)
    assert (info.format, info.fps_hz, info.bit_depth, info.width_px, info.height_px,
            info.n_frames) == ("Photron MRAW", 4500.0, bits, W, H, N)
    assert info.effective_bits == min(bits, 12)
    assert info.trigger_frame == 2 and info.first_frame_time_s == pytest.approx(-2 / 4500)
    assert "Record Rate(fps)" in info.fps_source or "recordRate" in info.fps_source
    assert str(mpath) in info.source
    if bits != 12:
        assert isinstance(got, np.memmap) or isinstance(got.base, np.memmap)
    if header == "cih":
        np.testing.assert_array_equal(_ref_read_mraw(hpath), frames)


@pytest.mark.parametrize("bits", [8, 12, 16])
def test_mraw_from_the_reference_writer(tmp_path, bits):
    frames = _frames(bits, seed=5)
    cih = _ref_write_mraw(tmp_path / "ref", frames, 4500, bits, start=0)
    got, info = read_mraw(cih, mmap=False)
    np.testing.assert_array_equal(got, frames)
    assert not isinstance(got, np.memmap)
    assert info.fps_hz == 4500 and info.trigger_frame == 0 and info.first_frame_time_s == 0


def test_mraw_12_bit_packing_by_hand(tmp_path):
    """Two pixels 0xABC, 0x123 are the bytes AB C1 23 (Photron's order)."""
    frames = np.array([[[0xABC, 0x123]]], dtype=np.uint16)
    _, mpath = write_mraw(tmp_path / "p", frames, 1000, 12)
    assert mpath.read_bytes() == bytes([0xAB, 0xC1, 0x23])
    frames16 = np.array([[[0x0102]]], dtype=np.uint16)
    _, mpath = write_mraw(tmp_path / "q", frames16, 1000, 16)
    assert mpath.read_bytes() == bytes([0x02, 0x01])   # little-endian words


def test_mraw_save_step_gives_no_rate(tmp_path):
    hpath, _ = write_mraw(tmp_path / "s", _frames(8), 60000, 8, start_frame=-72)
    hpath.write_text(hpath.read_text().replace("Save Step : 1", "Save Step : 36"))
    _, info = read_mraw(hpath)
    assert info.fps_hz is None and "Save Step" in info.fps_source
    assert info.trigger_frame == 2   # image numbers -72, -36, 0, ...


def _pymraw():
    return pytest.importorskip("pyMRAW")


@pytest.mark.parametrize("header", ["cih", "cihx"])
@pytest.mark.parametrize("bits", [8, 12, 16])
def test_pymraw_reads_our_files(tmp_path, bits, header):
    pm = _pymraw()
    frames = _frames(bits)
    hpath, _ = write_mraw(tmp_path / "rec", frames, 4500, bits, header=header)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        theirs, cih = pm.load_video(str(hpath))
    np.testing.assert_array_equal(np.asarray(theirs), frames)
    assert float(cih["Record Rate(fps)"]) == 4500 and cih["Color Bit"] == bits
    del theirs


@pytest.mark.parametrize("bits", [8, 16])
def test_we_read_pymraws_files(tmp_path, bits):
    pm = _pymraw()
    frames = _frames(bits)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        pm.save_mraw(frames, str(tmp_path / "pm.cih"), bit_depth=bits,
                     info_dict={"Record Rate(fps)": 4500})
    got, info = read_mraw(tmp_path / "pm.cih")
    np.testing.assert_array_equal(got, frames)
    assert info.fps_hz == 4500 and info.bit_depth == bits and info.n_frames == N


SAMPLES = os.environ.get("ABU_PHOTRON_SAMPLES")


@pytest.mark.skipif(not SAMPLES, reason="ABU_PHOTRON_SAMPLES (pyMRAW's data/ folder) not set")
@pytest.mark.parametrize("name,shape,bits,fps",
                         [("ball_12bit.cihx", (15, 384, 384), 12, 30000.0),
                          ("beam.cihx", (4, 80, 1024), 16, None)])
def test_real_photron_files(name, shape, bits, fps):
    got, info = read_mraw(Path(SAMPLES) / name)
    assert got.shape == shape and info.bit_depth == bits and info.fps_hz == fps
    assert info.effective_bits == 12 and int(got.max()) <= 4095  # 12 bits in little-endian words
    a = got.astype(float)   # a picture, not bit noise: neighbours are alike
    assert np.abs(np.diff(a, axis=2)).mean() < 0.5 * a.std()
    try:
        import pyMRAW as pm
    except ImportError:
        return
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        theirs, _ = pm.load_video(str(Path(SAMPLES) / name))
    np.testing.assert_array_equal(got, np.asarray(theirs))


# ------------------------------------------------------------------ CINE round trips
@pytest.mark.parametrize("bits", [8, 16])
@pytest.mark.parametrize("annotation", [0, 24])
def test_cine_round_trip_and_metadata(tmp_path, bits, annotation):
    frames = _frames(bits)
    path = write_cine(tmp_path / "rec.cine", frames, 4500, bits, first_image_no=-3,
                      trigger_time_unix_s=1_700_000_000.25, effective_bits=min(bits, 12),
                      annotation_bytes=annotation)
    got, info = read_cine(path)
    np.testing.assert_array_equal(got, frames)
    assert got.dtype == frames.dtype
    assert (info.format, info.fps_hz, info.bit_depth, info.width_px, info.height_px,
            info.n_frames) == ("Phantom CINE", 4500.0, bits, W, H, N)
    assert info.trigger_frame == 3 and info.first_frame_time_s == pytest.approx(-3 / 4500)
    assert info.trigger_time_unix_s == pytest.approx(1_700_000_000.25)
    assert info.effective_bits == min(bits, 12) and "FrameRate" in info.fps_source
    ref, meta = _ref_read_cine(path)
    np.testing.assert_array_equal(ref, frames)
    assert meta["fps"] == 4500 and meta["first_no"] == -3
    got2, _ = read_cine(path, mmap=False)
    np.testing.assert_array_equal(got2, frames)
    assert got2.flags.c_contiguous


@pytest.mark.parametrize("bits", [8, 16])
def test_cine_from_the_reference_writer(tmp_path, bits):
    frames = _frames(bits, seed=9)
    path = _ref_write_cine(tmp_path / "ref.cine", frames, 2000, first_no=10)
    got, info = read_cine(path)
    np.testing.assert_array_equal(got, frames)
    assert info.fps_hz == 2000 and info.trigger_frame is None
    assert info.first_frame_time_s == pytest.approx(10 / 2000) and info.trigger_time_unix_s is None


@pytest.mark.parametrize("bits", [8, 16])
def test_pims_reads_our_cine_and_the_reference_one(tmp_path, bits):
    pims = pytest.importorskip("pims")
    frames = _frames(bits)
    ours = write_cine(tmp_path / "ours.cine", frames, 4500, bits, first_image_no=-2,
                      trigger_time_unix_s=1_700_000_000.5, annotation_bytes=12)
    # pims reads the whole SETUP whatever its Length says: give it the full 7240 bytes
    ref = _ref_write_cine(tmp_path / "ref.cine", frames, 4500, first_no=-2, setup_length=7240)
    for path in (ours, ref):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            c = pims.Cine(str(path))
            try:
                theirs = np.stack([np.asarray(c.get_frame(i)) for i in range(len(c))])
                assert c.frame_rate == 4500 and c.header_dict["first_image_no"] == -2
                assert c.shape == (N, H, W)
            finally:
                c.close()
        np.testing.assert_array_equal(theirs, frames)
    assert read_cine(ours)[1].trigger_time_unix_s == pytest.approx(1_700_000_000.5)


# ------------------------------------------------------------------ read_recording hook
@pytest.mark.parametrize("kind", ["cih", "mraw", "cihx", "cine"])
def test_read_recording_dispatches_and_converts(tmp_path, kind):
    frames16 = _frames(12)      # 12-bit samples: one right shift by 4
    if kind == "cine":
        path = write_cine(tmp_path / "r.cine", frames16, 4500, 16, first_image_no=-1)
    else:
        hpath, mpath = write_mraw(tmp_path / "r", frames16, 4500, 12, start_frame=-1,
                                  header="cihx" if kind == "cihx" else "cih")
        path = mpath if kind == "mraw" else hpath
    rec = read_recording(path)
    assert rec.frames.dtype == np.uint8 and rec.shape == (N, H, W)
    np.testing.assert_array_equal(rec.frames, (frames16 >> 4).astype(np.uint8))
    assert "right shift by 4" in rec.source
    assert rec.fps_hz == 4500 and rec.fps_source and rec.bit_depth == (16 if kind == "cine"
                                                                       else 12)
    assert rec.first_frame_time_s == pytest.approx(-1 / 4500)


def test_read_recording_keeps_8_bit_camera_files_mapped(tmp_path):
    frames = _frames(8)
    hpath, _ = write_mraw(tmp_path / "r", frames, 4500, 8)
    rec = read_recording(hpath)
    assert rec.source.endswith("r.cih)")
    assert isinstance(rec.frames, np.memmap) or isinstance(rec.frames.base, np.memmap)
    cine = read_recording(write_cine(tmp_path / "r.cine", frames, 4500, 8))
    assert cine.frames.flags.c_contiguous and cine.frames.dtype == np.uint8
    np.testing.assert_array_equal(cine.frames, frames)


def test_video_container_rate_is_reported_not_taken(tmp_path):
    """A video container's rate is a playback rate (measurement.imaging.frame_rate): the
    recording states no rate, the container's is kept aside for the message."""
    import cv2

    path = tmp_path / "v.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 25.0, (W * 4, H * 4))
    for i in range(3):
        writer.write(np.full((H * 4, W * 4, 3), 40 * i, dtype=np.uint8))
    writer.release()
    rec = read_recording(path)
    assert rec.fps_hz is None and rec.container_fps_hz == pytest.approx(25.0)
    assert "playback rate" in rec.fps_source
    assert rec.bit_depth is None and rec.first_frame_time_s is None


def test_other_recordings_state_no_rate(tmp_path):
    from measurement.imaging.frames_io import write_npy
    rec = read_recording(write_npy(tmp_path / "s.npy", _frames(8)))
    assert rec.fps_hz is None and rec.fps_source is None and rec.bit_depth is None


# ------------------------------------------------------------------ errors
def _raises(call, path, *words) -> CameraFileError:
    with pytest.raises(CameraFileError) as info:
        call()
    err = info.value
    assert isinstance(err, RecordingError) and isinstance(err, AbuError)
    message = str(err)
    assert str(path) in message, message
    for word in words:
        assert word in message, (word, message)
    return err


def test_missing_header_and_missing_data(tmp_path):
    hpath, mpath = write_mraw(tmp_path / "r", _frames(8), 4500, 8)
    hpath.unlink()
    _raises(lambda: read_mraw(mpath), mpath, ".cih", ".cihx")
    with pytest.raises(RecordingError, match="no header beside it"):
        read_recording(mpath)
    hpath, mpath = write_mraw(tmp_path / "s", _frames(8), 4500, 8)
    mpath.unlink()
    _raises(lambda: read_mraw(hpath), hpath, ".mraw")
    _raises(lambda: read_camera_file(tmp_path / "x.avi"), tmp_path / "x.avi", "unknown")


@pytest.mark.parametrize("bits", [8, 12, 16])
def test_mraw_size_must_match_the_header(tmp_path, bits):
    hpath, mpath = write_mraw(tmp_path / "r", _frames(bits), 4500, bits)
    data = mpath.read_bytes()
    mpath.write_bytes(data[:-1])
    _raises(lambda: read_mraw(hpath), mpath, "truncated", str(len(data)))
    mpath.write_bytes(data + b"\0" * 3)
    _raises(lambda: read_mraw(hpath), mpath, "longer than the header")
    mpath.write_bytes(data)
    hpath.write_text(hpath.read_text().replace(f"Image Width : {W}", f"Image Width : {W + 2}"))
    _raises(lambda: read_mraw(hpath), mpath, "truncated", f"{W + 2}x{H} px")


@pytest.mark.parametrize("key,value,words", [
    ("Record Rate(fps)", "0", ["Record Rate(fps)", "frame rate"]),
    ("Record Rate(fps)", "-4500", ["Record Rate(fps)"]),
    ("Record Rate(fps)", "nan", ["Record Rate(fps)", "expected a number"]),
    ("Record Rate(fps)", "1e400", ["Record Rate(fps)", "finite"]),
    ("Record Rate(fps)", "fast", ["Record Rate(fps)"]),
    ("Color Bit", "10", ["Color Bit", "8, 12"]),
    ("Color Bit", "24", ["Color Bit", "colour"]),
    ("Color Type", "Color", ["Color Type", "colour"]),
    ("File Format", "TIFF", ["File Format", "MRaw"]),
    ("Total Frame", "0", ["Total Frame"]),
    ("Total Frame", "3.5", ["Total Frame"]),
    ("Total Frame", "999999999", ["Total Frame", "frames"]),
    ("Image Width", "-3", ["Image Width"]),
    ("Image Height", "70000", ["Image Height"]),
    ("EffectiveBit Depth", "13", ["EffectiveBit Depth"]),
    ("EffectiveBit Side", "Middle", ["EffectiveBit Side"]),
    ("Save Step", "0", ["Save Step"]),
])
def test_bad_cih_field_is_named(tmp_path, key, value, words):
    hpath, _ = write_mraw(tmp_path / "r", _frames(8), 4500, 8)
    lines = [f"{key} : {value}" if line.startswith(key + " :") else line
             for line in hpath.read_text().splitlines()]
    hpath.write_text("\n".join(lines) + "\n")
    err = _raises(lambda: read_mraw(hpath), hpath, *words)
    assert key in err.field


def test_missing_cih_field_and_garbage_headers(tmp_path):
    hpath, _ = write_mraw(tmp_path / "r", _frames(8), 4500, 8)
    text = hpath.read_text()
    hpath.write_text("\n".join(x for x in text.splitlines() if not x.startswith("Image Height")))
    _raises(lambda: read_mraw(hpath), hpath, "Image Height", "missing")
    hpath.write_bytes(bytes(range(256)) * 4)
    _raises(lambda: read_mraw(hpath), hpath, "Camera Information Header")
    xpath, _ = write_mraw(tmp_path / "x", _frames(8), 4500, 8, header="cihx")
    good = xpath.read_text()
    xpath.write_text(good.replace("<recordRate>4500</recordRate>", "<recordRate>0</recordRate>"))
    _raises(lambda: read_mraw(xpath), xpath, "<recordInfo/recordRate>")
    xpath.write_text(good.replace("</frameInfo>", ""))
    _raises(lambda: read_mraw(xpath), xpath, "<cih>", "XML")
    xpath.write_text("no xml here")
    _raises(lambda: read_mraw(xpath), xpath, "<cih>")
    xpath.write_text(good.replace("<cih>", '<cih><!DOCTYPE x [<!ENTITY a "aaaa">]>'))
    _raises(lambda: read_mraw(xpath), xpath, "XML")


def _cine_bytes(tmp_path, bits=8, **kw) -> tuple[Path, bytearray]:
    path = write_cine(tmp_path / "c.cine", _frames(bits), 4500, bits, **kw)
    return path, bytearray(path.read_bytes())


@pytest.mark.parametrize("offset,fmt,value,words", [
    (0, "2s", b"XX", ["Type", "CI"]),
    (2, "H", 40, ["Headersize"]),
    (4, "H", 1, ["Compression", "JPEG"]),
    (4, "H", 2, ["Compression"]),
    (6, "H", 0, ["Version"]),
    (20, "I", 0, ["ImageCount"]),
    (20, "I", 10**6, ["ImageCount"]),
    (24, "I", 10**9, ["OffImageHeader"]),
    (28, "I", 10**9, ["OffSetup"]),
    (32, "I", 10**9, ["OffImageOffsets"]),
    (44 + 4, "i", 0, ["biWidth"]),
    (44 + 8, "i", 0, ["biHeight"]),
    (44 + 14, "H", 24, ["biBitCount", "colour"]),
    (44 + 14, "H", 12, ["biBitCount"]),
    (44 + 16, "I", 256, ["biCompression", "packed 10-bit"]),
    (44 + 16, "I", 1024, ["biCompression", "packed 12-bit"]),
    (84 + 140, "2s", b"XY", ["SETUP Mark"]),
    (84 + 142, "H", 60000, ["SETUP Length"]),
    (84 + 896, "I", 17, ["RealBPP"]),
])
def test_bad_cine_field_is_named(tmp_path, offset, fmt, value, words):
    path, data = _cine_bytes(tmp_path)
    struct.pack_into("<" + fmt, data, offset, value)
    path.write_bytes(bytes(data))
    _raises(lambda: read_cine(path), path, *words)


def test_cine_rate_falls_back_to_framerate16_and_zero_is_refused(tmp_path):
    path, data = _cine_bytes(tmp_path)
    struct.pack_into("<I", data, 84 + 768, 0)
    path.write_bytes(bytes(data))
    _, info = read_cine(path)
    assert info.fps_hz == 4500 and "FrameRate16" in info.fps_source
    struct.pack_into("<H", data, 84, 0)
    path.write_bytes(bytes(data))
    _raises(lambda: read_cine(path), path, "FrameRate16", "frame rate")


def test_cine_image_table_and_annotations_are_checked(tmp_path):
    path, data = _cine_bytes(tmp_path)
    off_table = struct.unpack_from("<I", data, 32)[0]
    first = struct.unpack_from("<Q", data, off_table)[0]
    for field_offset, fmt, value, words in [
            (off_table + 8, "Q", len(data) + 10, ["pImage", "entry 1"]),
            (off_table + 8, "Q", 2**63 + 5, ["pImage", "entry 1"]),
            (first, "I", 0, ["image 0 AnnotationSize"]),
            (first, "I", 2**31, ["image 0 AnnotationSize"]),
            (first + 4, "I", 7, ["image 0 ImageSize", str(H * W)])]:
        bad = bytearray(data)
        struct.pack_into("<" + fmt, bad, field_offset, value)
        path.write_bytes(bytes(bad))
        _raises(lambda: read_cine(path), path, *words)


@pytest.mark.parametrize("cut", [0, 10, 50, 100, 2000, 7400, -1, -H * W - 3])
def test_truncated_cine_is_refused(tmp_path, cut):
    path, data = _cine_bytes(tmp_path)
    path.write_bytes(bytes(data[:cut]))
    _raises(lambda: read_cine(path), path)


def test_writers_refuse_bad_input(tmp_path):
    f8, f16 = _frames(8), _frames(16)
    for call, words in [
            (lambda: write_mraw(tmp_path / "a", f8, 4500, 10), ["bit_depth"]),
            (lambda: write_mraw(tmp_path / "a", f16, 4500, 8), ["uint8"]),
            (lambda: write_mraw(tmp_path / "a", f16, 4500, 12), ["4096"]),
            (lambda: write_mraw(tmp_path / "a", f8, 0, 8), ["fps_hz"]),
            (lambda: write_mraw(tmp_path / "a", f8[0], 4500, 8), ["(N, H, W)"]),
            (lambda: write_cine(tmp_path / "a.cine", f8, 4500.5, 8), ["whole number"]),
            (lambda: write_cine(tmp_path / "a.cine", f16, 4500, 12), ["bit_depth"]),
            (lambda: write_cine(tmp_path / "a.cine", f8, float("nan"), 8), ["fps_hz"])]:
        with pytest.raises(CameraFileError) as info:
            call()
        for word in words:
            assert word in str(info.value)
    assert not list(tmp_path.iterdir())   # nothing half-written


def test_fractional_mraw_rate_round_trips(tmp_path):
    hpath, _ = write_mraw(tmp_path / "r", _frames(8), 4499.5, 8)
    assert read_mraw(hpath)[1].fps_hz == 4499.5


# ------------------------------------------------------------------ fuzzing
flips = st.lists(st.tuples(st.floats(0, 1, exclude_max=True), st.integers(1, 255)),
                 min_size=1, max_size=4)


def _check_read(call) -> None:
    """Only our error, or frames whose shape and type the info states."""
    try:
        frames, info = call()
    except CameraFileError:
        return
    assert frames.shape == (info.n_frames, info.height_px, info.width_px)
    assert frames.dtype in (np.uint8, np.uint16)
    np.asarray(frames).sum()   # every byte is readable


@pytest.fixture(scope="module")
def cine_original(tmp_path_factory) -> bytes:
    d = tmp_path_factory.mktemp("cine_fuzz")
    return write_cine(d / "c.cine", _frames(16, n=4, h=6, w=8), 4500, 16, first_image_no=-1,
                      annotation_bytes=8).read_bytes()


@settings(max_examples=300, **SETTINGS)
@given(changes=flips, header_only=st.booleans())
def test_fuzzed_cine_headers_give_only_our_error(tmp_path, cine_original, changes, header_only):
    data = bytearray(cine_original)
    span = 84 + 1024 if header_only else len(data)   # CINEFILEHEADER, BITMAPINFO, SETUP start
    for where, xor in changes:
        data[int(where * span)] ^= xor
    path = tmp_path / "f.cine"
    path.write_bytes(bytes(data))
    _check_read(lambda: read_cine(path))


@settings(max_examples=100, **SETTINGS)
@given(cut=st.integers(0, 10**6))
def test_any_truncated_cine_is_refused(tmp_path, cine_original, cut):
    path = tmp_path / "t.cine"
    path.write_bytes(cine_original[:cut % len(cine_original)])
    with pytest.raises(CameraFileError):
        read_cine(path)


@settings(max_examples=100, **SETTINGS)
@given(blob=st.binary(max_size=400))
def test_garbage_cine_gives_only_our_error(tmp_path, blob):
    path = tmp_path / "g.cine"
    path.write_bytes(b"CI" + blob)
    _check_read(lambda: read_cine(path))


@pytest.fixture(scope="module")
def mraw_original(tmp_path_factory) -> tuple[Path, bytes, bytes]:
    d = tmp_path_factory.mktemp("mraw_fuzz")
    hpath, _ = write_mraw(d / "m", _frames(12, n=4, h=6, w=8), 4500, 12, start_frame=-1)
    xpath, mpath = write_mraw(d / "m", _frames(12, n=4, h=6, w=8), 4500, 12, header="cihx")
    return mpath.read_bytes(), hpath.read_bytes(), xpath.read_bytes()


@settings(max_examples=300, **SETTINGS)
@given(changes=flips, xml=st.booleans(), cut=st.floats(0.2, 1.0))
def test_fuzzed_cih_headers_give_only_our_error(tmp_path, mraw_original, changes, xml, cut):
    raw, cih, cihx = mraw_original
    data = bytearray(cihx if xml else cih)
    for where, xor in changes:
        data[int(where * len(data))] ^= xor
    header = tmp_path / ("m.cihx" if xml else "m.cih")
    header.write_bytes(bytes(data[:max(1, int(cut * len(data)))]))
    (tmp_path / "m.mraw").write_bytes(raw)
    _check_read(lambda: read_mraw(header))
