"""Reading and writing recordings: round trips and clear errors naming the file and frame."""
from __future__ import annotations

import cv2
import numpy as np
import pytest
import tifffile

from abu_model.errors import AbuError
from measurement.imaging.frames_io import (Recording, RecordingError, read_recording, write_frame_folder,
                                   write_multipage_tiff, write_npy)


@pytest.fixture(scope="module")
def stack() -> np.ndarray:
    """12 frames of 24x32 px with distinct content (each frame carries its index)."""
    rng = np.random.default_rng(7)
    frames = rng.integers(0, 256, size=(12, 24, 32), dtype=np.uint8)
    frames[:, 0, 0] = np.arange(12)
    return frames


def test_recording_error_is_an_abu_error():
    assert issubclass(RecordingError, AbuError)


def test_multipage_tiff_round_trip(tmp_path, stack):
    path = write_multipage_tiff(tmp_path / "rec.tif", stack)
    rec = read_recording(path)
    assert isinstance(rec, Recording)
    assert rec.frames.dtype == np.uint8 and rec.shape == stack.shape
    np.testing.assert_array_equal(rec.frames, stack)
    assert "TIFF" in rec.source and "rec.tif" in rec.source
    # no temporary file is left beside it
    assert sorted(f.name for f in tmp_path.iterdir()) == ["rec.tif"]


def test_contiguous_tiff_is_memory_mapped_and_other_layouts_are_read(tmp_path, stack):
    """An uncompressed stack (our writer's, a camera's) is mapped, not copied; a compressed,
    a big-endian 16-bit and a page-per-strip TIFF read to the same pixels."""
    plain = read_recording(write_multipage_tiff(tmp_path / "rec.tif", stack))
    assert isinstance(plain.frames, np.memmap)
    np.testing.assert_array_equal(plain.frames, stack)
    assert not isinstance(read_recording(tmp_path / "rec.tif", mmap=False).frames, np.memmap)
    wide = stack.astype(np.uint16) << 4                  # a 12-bit camera
    tifffile.imwrite(tmp_path / "be.tif", wide, byteorder=">")
    tifffile.imwrite(tmp_path / "le.tif", wide)
    tifffile.imwrite(tmp_path / "zip.tif", stack, compression="zlib")
    tifffile.imwrite(tmp_path / "strips.tif", stack, rowsperstrip=5)
    for name in ("be.tif", "le.tif", "zip.tif", "strips.tif"):
        rec = read_recording(tmp_path / name)
        np.testing.assert_array_equal(rec.frames, stack, err_msg=name)
    assert not isinstance(read_recording(tmp_path / "be.tif").frames, np.memmap)
    assert not isinstance(read_recording(tmp_path / "zip.tif").frames, np.memmap)


def test_npy_round_trip_is_memory_mapped(tmp_path, stack):
    path = write_npy(tmp_path / "rec.npy", stack)
    rec = read_recording(path)
    assert isinstance(rec.frames, np.memmap)
    np.testing.assert_array_equal(rec.frames, stack)
    np.testing.assert_array_equal(read_recording(path, mmap=False).frames, stack)


@pytest.mark.parametrize("suffix", [".png", ".bmp", ".tif"])
def test_folder_round_trip_in_natural_order(tmp_path, stack, suffix):
    # names frame0 .. frame11 without zero padding: plain sorting would put frame10 after frame1
    folder = write_frame_folder(tmp_path / "frames", stack, suffix=suffix)
    rec = read_recording(folder)
    np.testing.assert_array_equal(rec.frames[:, 0, 0], np.arange(12))
    np.testing.assert_array_equal(rec.frames, stack)
    assert rec.frame_names[10] == f"frame10{suffix}"


def test_folder_holding_one_stack_reads_the_stack(tmp_path, stack):
    write_multipage_tiff(tmp_path / "frames.tif", stack)
    (tmp_path / "meta.json").write_text("{}")
    np.testing.assert_array_equal(read_recording(tmp_path).frames, stack)


def test_video_is_read_as_grayscale(tmp_path):
    # a smooth pattern survives lossy MJPG coding to within a few grey levels
    yy, xx = np.mgrid[0:64, 0:80]
    frames = np.stack([((xx + 3 * k) * 2 % 200 + 20).astype(np.uint8) for k in range(5)])
    path = tmp_path / "rec.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (80, 64))
    if not writer.isOpened():
        pytest.skip("this OpenCV build cannot write MJPG video")
    for f in frames:
        writer.write(cv2.cvtColor(f, cv2.COLOR_GRAY2BGR))
    writer.release()
    rec = read_recording(path)
    assert rec.shape == frames.shape and rec.frames.dtype == np.uint8
    assert np.median(np.abs(rec.frames.astype(int) - frames)) <= 3


def test_nonexistent_path(tmp_path):
    with pytest.raises(RecordingError, match="nope.tif' does not exist"):
        read_recording(tmp_path / "nope.tif")


def test_empty_folder(tmp_path):
    (tmp_path / "notes.txt").write_text("no frames here")
    with pytest.raises(RecordingError, match="holds no frames"):
        read_recording(tmp_path)


def test_unreadable_frame_is_named(tmp_path, stack):
    folder = write_frame_folder(tmp_path / "f", stack[:5])
    (folder / "frame3.png").write_bytes(b"not a png at all")
    with pytest.raises(RecordingError, match=r"frame 3 .*frame3\.png.* unreadable"):
        read_recording(folder)


def test_missing_frame_number_is_named(tmp_path, stack):
    folder = write_frame_folder(tmp_path / "f", stack[:6])
    (folder / "frame4.png").unlink()
    with pytest.raises(RecordingError, match=r"frame number 4 is missing .*frame3\.png.*frame5\.png"):
        read_recording(folder)


def test_colour_and_sixteen_bit_recordings_are_converted(tmp_path, stack):
    """What high-speed cameras write: 10-16 bit grey in 16-bit containers, colour (RGB TIFF,
    BGR PNG, RGB .npy), read as the 8-bit grey frames they carry (the same pixels for grey
    content, one shift for the whole recording), and the source says what was converted."""
    tall = stack.astype(np.uint16) * 16 + 7          # a 12-bit camera: 0..4095
    tifffile.imwrite(tmp_path / "g16.tif", tall, photometric="minisblack")
    rgb = np.repeat(stack[..., None], 3, axis=-1)
    tifffile.imwrite(tmp_path / "rgb.tif", rgb, photometric="rgb")
    tifffile.imwrite(tmp_path / "rgb16.tif", rgb.astype(np.uint16) * 256, photometric="rgb")
    np.save(tmp_path / "rgb.npy", rgb)
    np.save(tmp_path / "g16.npy", tall)
    png16 = tmp_path / "png16"
    png16.mkdir()
    pngc = tmp_path / "pngc"
    pngc.mkdir()
    for i in range(4):
        cv2.imwrite(str(png16 / f"f{i}.png"), tall[i])
        cv2.imwrite(str(pngc / f"f{i}.png"), rgb[i][..., ::-1])   # OpenCV writes BGR
    expect = {"g16.tif": "right shift by 4", "rgb.tif": "colour to grey",
              "rgb16.tif": "right shift by 8", "rgb.npy": "colour to grey",
              "g16.npy": "right shift by 4", "png16": "right shift by 4",
              "pngc": "colour to grey"}
    for name, note in expect.items():
        rec = read_recording(tmp_path / name)
        n = len(rec)
        assert rec.frames.dtype == np.uint8 and rec.frames.shape == (n,) + stack.shape[1:]
        np.testing.assert_array_equal(rec.frames, stack[:n])
        assert note in rec.source, rec.source
    # colour weights: pure red, green and blue give the BT.601 luma of each, in either order
    colours = np.zeros((3, 24, 32, 3), np.uint8)
    for k in range(3):
        colours[k, ..., k] = 200
    np.save(tmp_path / "rgbk.npy", colours)
    got = read_recording(tmp_path / "rgbk.npy").frames[:, 0, 0]
    np.testing.assert_array_equal(got, np.rint(200 * np.array([0.299, 0.587, 0.114])))
    cv2.imwrite(str(tmp_path / "red.png"), colours[0][..., ::-1])
    assert read_recording(tmp_path / "red.png").frames[0, 0, 0] == round(200 * 0.299)


def test_sixteen_bit_frame_among_eight_bit_ones_is_named(tmp_path, stack):
    folder = write_frame_folder(tmp_path / "f", stack[:4])
    cv2.imwrite(str(folder / "frame1.png"), np.zeros((24, 32), np.uint16))
    with pytest.raises(RecordingError, match=r"frame 1 .*frame1\.png.* uint16.*uint8"):
        read_recording(folder)


def test_differing_frame_size_is_named(tmp_path, stack):
    folder = write_frame_folder(tmp_path / "f", stack[:4])
    cv2.imwrite(str(folder / "frame3.png"), np.zeros((20, 32), np.uint8))
    with pytest.raises(RecordingError, match=r"frame 3 .*frame3\.png.* 32x20 px"):
        read_recording(folder)


def test_npy_wrong_dtype_and_shape(tmp_path):
    np.save(tmp_path / "f.npy", np.zeros((3, 8, 8), np.float32))
    with pytest.raises(RecordingError, match=r"f\.npy.*float32.*uint8"):
        read_recording(tmp_path / "f.npy")
    np.save(tmp_path / "c.npy", np.zeros((3, 8, 8, 5), np.uint8))   # 5 samples: no colour
    with pytest.raises(RecordingError, match=r"c\.npy.*\(3, 8, 8, 5\)"):
        read_recording(tmp_path / "c.npy")
    np.save(tmp_path / "i.npy", np.zeros((3, 8, 8), np.int32))
    with pytest.raises(RecordingError, match=r"i\.npy.*int32.*uint8 or uint16"):
        read_recording(tmp_path / "i.npy")


def test_tiff_wrong_dtype_and_differing_pages(tmp_path):
    tifffile.imwrite(tmp_path / "d.tif", np.zeros((4, 8, 8), np.float32), photometric="minisblack")
    with pytest.raises(RecordingError, match=r"d\.tif.*float32"):
        read_recording(tmp_path / "d.tif")
    with tifffile.TiffWriter(tmp_path / "p.tif") as tw:
        tw.write(np.zeros((8, 8), np.uint8))
        tw.write(np.zeros((8, 8), np.uint8))
        tw.write(np.zeros((6, 8), np.uint8))
    with pytest.raises(RecordingError, match=r"p\.tif.*frame 2 has shape \(6, 8\)"):
        read_recording(tmp_path / "p.tif")


def test_corrupt_tiff_and_unknown_file(tmp_path):
    (tmp_path / "x.tif").write_bytes(b"II*\x00garbage")
    with pytest.raises(RecordingError, match=r"x\.tif"):
        read_recording(tmp_path / "x.tif")
    (tmp_path / "x.dat").write_bytes(b"\x00" * 100)
    with pytest.raises(RecordingError, match=r"cannot read .*x\.dat"):
        read_recording(tmp_path / "x.dat")


def test_failed_write_leaves_nothing(tmp_path):
    with pytest.raises(RecordingError, match="float64"):
        write_multipage_tiff(tmp_path / "bad.tif", np.zeros((2, 4, 4)))
    assert list(tmp_path.iterdir()) == []


def test_conversion_in_blocks_equals_the_whole_array_conversion():
    """sample_formats converts long recordings block by block (no full-size temporaries):
    the result over several blocks is the whole-array shift / luma, exactly."""
    from measurement.imaging import sample_formats as fmt

    rng = np.random.default_rng(0)
    n = 2 * fmt.BLOCK_FRAMES + 3
    tall = rng.integers(0, 4096, (n, 7, 9)).astype(np.uint16)
    out, note = fmt.to_uint8(tall)
    np.testing.assert_array_equal(out, (tall >> 4).astype(np.uint8))
    assert "largest 4095" in note and "shift by 4" in note
    rgb = rng.integers(0, 256, (n, 7, 9, 4)).astype(np.uint8)      # alpha ignored
    w = np.array(fmt.LUMA_RGB, np.float32)
    expect = np.clip(np.rint(rgb[..., :3].astype(np.float32) @ w), 0, 255).astype(np.uint8)
    np.testing.assert_array_equal(fmt.luma(rgb, "RGB"), expect)
    bgr = rgb[..., 2::-1]
    expect_bgr = np.clip(np.rint(bgr.astype(np.float32) @ w[::-1]), 0, 255).astype(np.uint8)
    np.testing.assert_array_equal(fmt.luma(bgr, "BGR"), expect_bgr)
    assert np.abs(expect_bgr.astype(int) - expect).max() <= 1     # summation order only


def test_fast_tiff_check_accepts_only_what_the_page_by_page_check_accepts(tmp_path, stack,
                                                                           monkeypatch):
    """The vectorised check of the page headers (recording_checks._uniform_stack_whole) takes
    our writer's stack, big-endian and BigTIFF ones too; on 300 seeded damaged copies (cuts and
    bit flips in the page headers and next-page pointers, flips in the pixels) every file is
    refused with the same message or read to the same pixels as with the fast check off."""
    from measurement.imaging import recording_checks as rc

    fast_calls = []
    real = rc._uniform_stack_whole

    def spy(*a):
        fast_calls.append(real(*a))
        return fast_calls[-1]

    layouts = {"ours.tif": {}, "be.tif": {"byteorder": ">"}, "big.tif": {"bigtiff": True}}
    for name, kw in layouts.items():
        tifffile.imwrite(tmp_path / name, stack, photometric="minisblack", contiguous=True, **kw)
        with tifffile.TiffFile(tmp_path / name) as tif:
            len(tif.pages)
            assert real(tmp_path / name, tif, (tmp_path / name).stat().st_size), name

    def outcome(path, fast: bool):
        monkeypatch.setattr(rc, "_uniform_stack_whole", spy if fast else (lambda *a: False))
        try:
            return np.asarray(read_recording(path).frames).tobytes()
        except RecordingError as exc:
            return str(exc)

    original = (tmp_path / "ours.tif").read_bytes()
    with tifffile.TiffFile(tmp_path / "ours.tif") as tif:
        headers = [(pg.offset, pg.offset + 2 + 12 * len(pg.tags) + 4) for pg in tif.pages[1:]]
    rng = np.random.default_rng(20)
    accepted = 0
    for case in range(300):
        data = bytearray(original)
        if case % 3 == 0:
            data = data[:int(rng.integers(len(data) // 2, len(data)))]
        elif case % 3 == 1:   # a flip in the pixels: a whole file, taken by the fast check
            data[int(rng.integers(headers[0][0] - stack[0].size, headers[0][0]))] ^= 0x10
        else:
            lo, hi = headers[int(rng.integers(len(headers)))]
            pos = int(rng.integers(lo, hi))
            data[pos] ^= 1 << int(rng.integers(8))
        path = tmp_path / "damaged.tif"
        path.write_bytes(bytes(data))
        fast_calls.clear()
        with_fast = outcome(path, True)
        accepted += any(fast_calls)
        assert with_fast == outcome(path, False), case
    assert accepted >= 100  # at least the pixel flips
