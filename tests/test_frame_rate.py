"""The frame rate from the file (issue 20): camera files measured end to end, rates stated and
given, and files that state none refused with a message naming ``--fps``.

* One twin recording (800 frames at 2000 frames/s, rendered by ``abu render``) is written as
  Photron MRAW with a CIH and a CIHX header at 8, 12 and 16 bits and as Phantom CINE at 8 and
  16 bits (the 12- and 16-bit samples are the 8-bit frames shifted up, with random low bits
  the reader's conversion must drop); each is read back frame for frame identical and measured
  by ``abu measure`` with the interval of the TIFF of the same frames, at the rate the header
  states (no ``--fps``).
* A CIH at 2000 frames/s gives 0.5 ms steps in tracks.csv and names its field as the source;
  ``--fps`` differing from it warns once on stderr and is used.
* Video (its container's rate is a playback rate), ``.npy``, frame folders and TIFFs without our
  metadata are refused without ``--fps``, naming the option and the file; the API names
  ``fps_hz``.
"""
from __future__ import annotations

import json
import math
import re
import shutil
import warnings

import numpy as np
import pytest

from abu.cli.main import main
from measurement.imaging.camera_files import read_camera_file, write_cine, write_mraw
from measurement.imaging.frame_rate import MissingFrameRateError
from measurement.imaging.recording_checks import RecordingError
from measurement.imaging.frames_io import (read_recording, write_frame_folder,
                                           write_multipage_tiff, write_npy)
from measurement.imaging.tracks_io import read_tracks_csv

FPS = 2000.0
N_FRAMES = 800


@pytest.fixture(scope="module")
def twin(tmp_path_factory, fmu_dir):
    """(frames (N, H, W) uint8, seeds text, folder) of a twin rendered at 2000 frames/s."""
    out = tmp_path_factory.mktemp("twin") / "rec"
    fmus = next(iter(fmu_dir.values())).parent
    assert main(["render", "--out", str(out), "--frames", str(N_FRAMES), "--fps", str(FPS),
                 "--seed", "3", "--fmu-dir", str(fmus), "--quiet"]) == 0
    meta = json.loads((out / "meta.json").read_text())
    frames = np.array(read_recording(out / "frames.tif").frames)
    assert frames.max() >= 128   # the 16-bit copy's shift by 8 is then the reader's
    return frames, meta["seeds"], out


def _measure(path, out, capsys, *extra):
    assert main(["measure", str(path), "--out", str(out), "--json", "--no-plots",
                 "--mc-draws", "0", "--quiet", *extra]) == 0, capsys.readouterr().err
    return json.loads(capsys.readouterr().out)


def _camera_copy(kind: str, bits: int, frames: np.ndarray, folder):
    """The frames as a camera file of ``bits`` bits (higher depths: shifted up, random low
    bits); returns (path to give, the samples written)."""
    rng = np.random.default_rng(bits)
    if bits == 8:
        samples = frames
    else:
        shift = bits - 8
        samples = (frames.astype(np.uint16) << shift) | rng.integers(
            0, 2 ** shift, size=frames.shape, dtype=np.uint16)
    if kind == "cine":
        return write_cine(folder / "rec.cine", samples, int(FPS), bits, first_image_no=-5), samples
    hpath, _ = write_mraw(folder / "rec", samples, FPS, bits, start_frame=-5, header=kind)
    return hpath, samples


def test_camera_files_measure_as_the_tiff_of_the_same_frames(twin, tmp_path, capsys):
    frames, seeds, _ = twin
    tif = write_multipage_tiff(tmp_path / "plain.tif", frames)   # no rate stored
    ref = _measure(tif, tmp_path / "m_tif", capsys, "--fps", str(FPS), "--seeds", seeds)
    assert ref["input"]["fps_source"] == "--fps (given)"
    assert ref["mu_low"] is not None and ref["mu_high"] is not None
    cases = [("cih", 8), ("cih", 12), ("cih", 16), ("cihx", 12), ("cine", 8), ("cine", 16)]
    for kind, bits in cases:
        folder = tmp_path / f"{kind}{bits}"
        folder.mkdir()
        path, samples = _camera_copy(kind, bits, frames, folder)
        raw, info = read_camera_file(path)
        np.testing.assert_array_equal(raw, samples)                       # native depth
        np.testing.assert_array_equal(read_recording(path).frames, frames)  # as tracked
        del raw
        s = _measure(path, tmp_path / f"m_{kind}{bits}", capsys, "--seeds", seeds)
        assert (s["mu_low"], s["mu_high"]) == (ref["mu_low"], ref["mu_high"]), (kind, bits)
        assert s["status"] == ref["status"]
        inp = s["input"]
        assert inp["fps_hz"] == FPS and inp["bit_depth"] == bits
        field = "FrameRate" if kind == "cine" else "Record Rate(fps)" if kind == "cih" \
            else "recordRate"
        assert field in inp["fps_source"], inp["fps_source"]
        assert inp["first_frame_time_s"] == pytest.approx(-5 / FPS)
        shutil.rmtree(folder)   # ~100 MB each


def test_twin_tiff_states_its_rate_and_a_render_meta_json_backs_an_old_one(twin, tmp_path,
                                                                            capsys):
    frames, seeds, folder = twin
    rec = read_recording(folder / "frames.tif")
    assert rec.fps_hz == FPS and "ImageDescription" in rec.fps_source
    assert rec.first_frame_time_s == 0.0
    # A render written before the TIFF carried the rate: meta.json beside it states it.
    old = tmp_path / "old"
    old.mkdir()
    write_multipage_tiff(old / "frames.tif", frames[:300])
    shutil.copy(folder / "meta.json", old / "meta.json")
    rec = read_recording(old)
    assert rec.fps_hz == FPS and rec.fps_source.startswith("meta.json 'fps'")
    # ... but only for the file it names.
    (old / "frames.tif").rename(old / "other.tif")
    assert read_recording(old / "other.tif").fps_hz is None


def _small_stack(n=60):
    render = pytest.importorskip("twin.render")
    geo = render.CameraGeometry()
    c, cd, ball = geo.marker_positions(-2 * math.pi * 9 * np.arange(n) / 4500, np.full(n, 0.6))
    return render.render_frames(c, cd, ball, render.RenderSettings(), seed=1)


def test_cih_rate_sets_the_time_step_and_a_differing_fps_warns(tmp_path, capsys):
    frames = _small_stack()
    hpath, _ = write_mraw(tmp_path / "cam", frames, 2000, 8)
    assert main(["track", str(hpath), "--out", str(tmp_path / "t"), "--quiet"]) == 0
    assert capsys.readouterr().err == ""
    tr = read_tracks_csv(tmp_path / "t" / "tracks.csv")
    np.testing.assert_allclose(np.diff(tr.time), 0.5e-3, rtol=1e-9)
    info = json.loads((tmp_path / "t" / "tracking.json").read_text())
    assert info["fps_hz"] == 2000 and "Record Rate(fps)" in info["fps_source"]
    assert info["bit_depth"] == 8
    # --fps overrides, with one warning line on stderr (even with --quiet).
    assert main(["track", str(hpath), "--out", str(tmp_path / "t2"), "--fps", "4000",
                 "--quiet"]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("warning: --fps 4000") and "2000" in err[0]
    tr = read_tracks_csv(tmp_path / "t2" / "tracks.csv")
    np.testing.assert_allclose(np.diff(tr.time), 0.25e-3, rtol=1e-9)
    info = json.loads((tmp_path / "t2" / "tracking.json").read_text())
    assert info["fps_hz"] == 4000 and info["fps_source"] == "--fps (given)"
    assert info["fps_stated_hz"] == 2000
    # The same rate given: no warning.
    assert main(["track", str(hpath), "--out", str(tmp_path / "t3"), "--fps", "2000",
                 "--quiet"]) == 0
    assert capsys.readouterr().err == ""


def _video(path, frames, fps):
    cv2 = pytest.importorskip("cv2")
    fourcc = cv2.VideoWriter_fourcc(*("mp4v" if path.suffix == ".mp4" else "MJPG"))
    h, w = frames.shape[1:]
    writer = cv2.VideoWriter(str(path), fourcc, fps, (w, h), False)
    for f in frames:
        writer.write(f)
    writer.release()
    if not path.exists() or path.stat().st_size == 0:
        pytest.skip(f"OpenCV cannot write {path.suffix} here")
    return path


@pytest.mark.parametrize("suffix", [".avi", ".mp4"])
def test_video_without_fps_is_refused_naming_the_option(tmp_path, capsys, suffix):
    frames = _small_stack(30)
    path = _video(tmp_path / f"v{suffix}", frames, 30.0)
    out = tmp_path / "o"
    assert main(["track", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--fps" in err and str(path) in err
    assert "30 frames/s" in err and "playback" in err and "Traceback" not in err
    assert not out.exists()
    assert main(["track", str(path), "--out", str(out), "--fps", "4500", "--quiet"]) == 0
    info = json.loads((out / "tracking.json").read_text())
    assert info["fps_hz"] == 4500 and info["video_container_fps_hz"] == pytest.approx(30.0)


def test_sources_without_a_rate_need_fps(tmp_path, capsys):
    frames = _small_stack(25)
    sources = {"npy": write_npy(tmp_path / "r.npy", frames),
               "folder": write_frame_folder(tmp_path / "frames", frames),
               "tiff": write_multipage_tiff(tmp_path / "r.tif", frames)}
    for name, path in sources.items():
        for command in ("track", "measure"):
            out = tmp_path / f"{command}_{name}"
            assert main([command, str(path), "--out", str(out)]) == 2, (command, name)
            err = capsys.readouterr().err.strip()
            assert len(err.splitlines()) == 1, err
            assert "--fps" in err and str(path) in err and "no frame rate" in err, err
            assert not out.exists()


def test_api_follows_the_same_rule(tmp_path):
    from abu import api

    frames = _small_stack(40)
    npy = write_npy(tmp_path / "r.npy", frames)
    with pytest.raises(MissingFrameRateError, match=r"fps_hz.*r\.npy|r\.npy.*fps_hz"):
        api.track(npy)
    tracks = api.track(npy, fps_hz=3000)
    assert tracks.info["fps_hz"] == 3000 and tracks.time_s[1] == pytest.approx(1 / 3000)
    cine = write_cine(tmp_path / "r.cine", frames, 1000, 8)
    assert api.track(cine).info["fps_source"] == "CINE header 'SETUP FrameRate'"
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert api.track(cine, fps_hz=1200).info["fps_hz"] == 1200
    assert [str(w.message) for w in caught if "fps_hz 1200" in str(w.message)]


def test_one_frame_rate_limit_for_options_library_files_and_plans(tmp_path, capsys):
    """The command line, the library, the camera-file readers and `abu design` refuse a rate
    above the same figure (abu_model.params.MAX_CAMERA_FPS_HZ; the library used to take 1e8
    and design 1e6) and accept one at it."""
    from abu import api
    from abu_model.errors import ParameterError
    from abu_model.params import MAX_CAMERA_FPS_HZ
    from measurement.imaging.camera_file_common import CameraFileError

    too_fast = 2 * MAX_CAMERA_FPS_HZ
    frames = _small_stack(25)
    npy = write_npy(tmp_path / "r.npy", frames)
    assert main(["track", str(npy), "--out", str(tmp_path / "o"), "--fps", f"{too_fast:g}"]) == 2
    err = capsys.readouterr().err.strip()
    assert "--fps" in err and f"{MAX_CAMERA_FPS_HZ:g}" in err
    with pytest.raises(ParameterError, match=re.escape(f"{MAX_CAMERA_FPS_HZ:g}")):
        api.track(npy, fps_hz=too_fast)
    assert main(["design", "--mu-range", "0.02", "0.04", "--fps", f"{too_fast:g}"]) == 2
    assert "--fps" in capsys.readouterr().err
    # the tracking drive's design too (it had its own check, at 1e6)
    tracking = tmp_path / "tracking.json"
    tracking.write_text(json.dumps({"kind": "abu-drive", "format_version": 1,
                                    "model": "tracking", "bandwidth_rad_s": 150.0}))
    assert main(["design", "--mu-range", "0.02", "0.04", "--drive", str(tracking),
                 "--fps", f"{too_fast:g}"]) == 2
    assert "'--fps'" in capsys.readouterr().err
    # 2e6 frames/s passes the rate check (a 3072-frame record is then too short to design in)
    main(["design", "--mu-range", "0.02", "0.04", "--drive", str(tracking), "--fps", "2e6"])
    assert "'--fps'" not in capsys.readouterr().err
    hpath, _ = write_mraw(tmp_path / "cam", frames, 2000, 8)
    text = hpath.read_text().replace("Record Rate(fps) : 2000",
                                     f"Record Rate(fps) : {too_fast:.0f}")
    assert str(int(too_fast)) in text
    hpath.write_text(text)
    with pytest.raises(CameraFileError, match="Record Rate"):
        read_camera_file(hpath)
    # at the limit: accepted by the library
    tracks = api.track(npy, fps_hz=MAX_CAMERA_FPS_HZ)
    assert tracks is not None


def test_the_twin_at_2000_frames_per_second_holds_its_mu(twin, tmp_path, capsys):
    """Its true mu (meta.json) lies in the measured interval: before omega_dot's noise entered
    the predicted slip (tests/test_drive_noise.py) it gave [0.03014, 0.03482] for mu = 0.03."""
    _, _, folder = twin
    s = _measure(folder, tmp_path / "m", capsys)
    mu = json.loads((folder / "meta.json").read_text())["mu"]
    assert s["mu_low"] <= mu <= s["mu_high"], (s["mu_low"], s["mu_high"], mu)


def test_cine_image_times_dropped_frames_refused_jitter_within_tolerance_read(tmp_path, capsys):
    """A CINE's time block (tagged block 1002) records when each image was taken. The analysis
    takes frame i at t0 + i / fps: a dropped frame (image 30 missing, so images 29 and 30 are
    two intervals apart) is refused with exit status 2, naming the file and the block;
    images within 1 % of an interval of the grid (a camera clock's jitter) are read."""
    frames = _small_stack()
    n, fps, t0 = frames.shape[0], 4500, 1.7e9
    dropped = t0 + (np.arange(n) + (np.arange(n) >= 30)) / fps
    path = write_cine(tmp_path / "dropped.cine", frames, fps, 8, trigger_time_unix_s=t0,
                      image_times_s=dropped)
    assert main(["track", str(path), "--out", str(tmp_path / "t"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert str(path) in err and "tagged block 1002" in err and "images 29 and 30" in err, err
    assert "2 frame intervals" in err and not (tmp_path / "t").exists()
    jitter = t0 + (np.arange(n) + np.random.default_rng(0).uniform(-0.01, 0.01, n)) / fps
    path = write_cine(tmp_path / "jitter.cine", frames, fps, 8, trigger_time_unix_s=t0,
                      image_times_s=jitter)
    rec = read_recording(path)
    assert rec.fps_hz == fps and np.array_equal(np.asarray(rec.frames), frames)
    # at 300,000 frames/s (3.33 us apart), times kept to a 1 us clock (3 or 4 us apart) are
    # read; a dropped frame is refused
    fast = np.round((t0 + np.arange(n) / 300_000) * 1e6) / 1e6
    read_recording(write_cine(tmp_path / "fast.cine", frames, 300_000, 8,
                              trigger_time_unix_s=t0, image_times_s=fast))
    with pytest.raises(RecordingError, match="images 9 and 10"):
        read_recording(write_cine(tmp_path / "fast.cine", frames, 300_000, 8,
                                  trigger_time_unix_s=t0,
                                  image_times_s=fast + (np.arange(n) >= 10) / 300_000))
    # the default writer's evenly spaced times, with or without a trigger time, are read
    for kw in ({}, {"trigger_time_unix_s": t0}, {"first_image_no": -n + 1}):
        read_recording(write_cine(tmp_path / "even.cine", frames, fps, 8, **kw))
