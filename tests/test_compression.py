"""Lossy recordings are detected and named (measurement.imaging.compression): videos written by
OpenCV with lossy codecs (mp4v, MJPG, XVID) are flagged from the container's codec *and* from
the pixels alone; lossless ones (FFV1, PNG in AVI, TIFF, .npy) are not."""
from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from measurement.imaging import compression as C
from measurement.imaging.frames_io import read_recording


@pytest.fixture(scope="module")
def twin_frames():
    from twin.scenario import random_scenario, render_scenario_frames, simulate_scenario

    scn = random_scenario(3, size=200).with_(n_frames=120)
    st, pos = simulate_scenario(scn)
    return render_scenario_frames(scn, st, pos)


def write_video(path, frames, fourcc):
    w = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*fourcc), 30.0,
                        (frames.shape[2], frames.shape[1]), isColor=False)
    assert w.isOpened(), fourcc
    for f in frames:
        w.write(f)
    w.release()


@pytest.mark.parametrize("fourcc,ext", [("mp4v", "mp4"), ("MJPG", "avi"), ("XVID", "avi")])
def test_lossy_videos_are_flagged_by_codec_and_by_pixels(tmp_path, twin_frames, fourcc, ext):
    path = tmp_path / f"rec.{ext}"
    write_video(path, twin_frames, fourcc)
    rec = read_recording(path)
    comp = C.detect(rec.frames, rec.codec)
    assert rec.codec is not None and comp.codec_lossy, rec.codec
    # from the pixels alone (e.g. the same frames re-saved as PNG): the 8x8 block edges
    pixels = C.detect(rec.frames, None)
    assert pixels.block_coded and pixels.lossy, pixels
    assert pixels.block_edge_ratio > 1.15
    status = C.lossy_status("ok", comp.summary())
    assert status.startswith("lossy compression") and rec.codec in status


@pytest.mark.parametrize("fourcc,ext", [("FFV1", "avi"), ("PNG ", "avi")])
def test_lossless_videos_are_not_flagged(tmp_path, twin_frames, fourcc, ext):
    path = tmp_path / f"rec.{ext}"
    write_video(path, twin_frames, fourcc)
    rec = read_recording(path)
    np.testing.assert_array_equal(rec.frames, twin_frames)      # truly lossless
    comp = C.detect(rec.frames, rec.codec)
    assert not comp.lossy, comp
    assert comp.block_edge_ratio < C.BLOCK_EDGE_LIMIT
    assert C.lossy_status("ok", comp.summary()) == "ok"


def test_tiff_and_noise_free_frames_are_not_flagged(tmp_path, twin_frames):
    from measurement.imaging.frames_write import write_multipage_tiff as write_tiff

    path = tmp_path / "rec.tif"
    write_tiff(path, twin_frames)
    rec = read_recording(path)
    assert rec.codec is None and not C.detect(rec.frames, rec.codec).lossy
    # a noise-free scene repeats static blocks exactly: no sensor noise, no evidence ...
    yy, xx = np.mgrid[0:200, 0:200]
    smooth = np.broadcast_to((60 + 0.3 * xx + 0.1 * yy).astype(np.uint8), (40, 200, 200))
    assert C.detect(smooth).noise_dn < C.NOISE_FLOOR_DN and not C.detect(smooth).lossy
    # ... but noisy frames repeated block for block are what inter-frame coding leaves
    copied = np.array(twin_frames[:40])
    copied[1::2, :96, :96] = copied[0::2, :96, :96]
    comp = C.detect(copied)
    assert comp.inter_frame and comp.lossy and "frozen" in comp.evidence()


def test_fourcc_text():
    assert C.fourcc_text(cv2.VideoWriter_fourcc(*"MJPG")) == "MJPG"
    assert C.fourcc_text(0) is None and C.fourcc_text(float("nan")) is None


def test_abu_track_records_the_compression(tmp_path, twin_frames):
    from abu.cli.main import main
    from twin.scenario import random_scenario, simulate_scenario
    from measurement.imaging.markers import format_seeds

    scn = random_scenario(3, size=200).with_(n_frames=120)
    _, pos = simulate_scenario(scn)
    seeds = format_seeds(np.stack([pos["centre"][0], pos["cd"][0], pos["ball"][0]]))
    for fourcc, ext, lossy in (("MJPG", "avi", True), ("FFV1", "avi", False)):
        path = tmp_path / f"rec_{fourcc}.{ext}"
        write_video(path, twin_frames, fourcc)
        out = tmp_path / f"t_{fourcc}"
        assert main(["track", str(path), "--out", str(out), "--seeds", seeds, "--fps", "4500",
                     "--quiet"]) == 0
        info = json.loads((out / "tracking.json").read_text())
        assert info["compression"]["lossy"] is lossy, info["compression"]


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_integer_statistics_equal_numpys_float_ones(dtype):
    """The histogram quantiles of 8/16-bit frames (the fast path) give NumPy's sorted-data
    quantiles: the same statistics as the frames converted to float (NumPy's path)."""
    rng = np.random.default_rng(7)
    top = np.iinfo(dtype).max
    for trial in range(40):
        v = rng.integers(0, rng.integers(1, top + 1), rng.integers(1, 4000)).astype(dtype)
        q = rng.random()
        diffs = np.abs(np.diff(v.astype(np.int32)))
        if diffs.size:
            assert C._quantile(diffs, q) == pytest.approx(np.quantile(diffs, q), rel=1e-12)
        scale = rng.uniform(0.5, 0.2 * top)
        frames = rng.normal(top / 2, scale, (4, 40, 48)).clip(0, top).astype(dtype)
        as_float = frames.astype(np.float64)
        assert C.block_edge_ratio(frames) == pytest.approx(C.block_edge_ratio(as_float),
                                                            rel=1e-6)
        assert C.noise_dn(frames) == pytest.approx(C.noise_dn(as_float), rel=1e-6)
