"""Property-based fuzzing of the readers with mutated files (issue 11).

Recordings (multi-page TIFF of our writer, OpenCV's multi-page TIFF, .npy), tracks CSV,
summary JSON and ``abu identify --pulses`` pulse-time files are truncated, bit-flipped,
spliced. Properties:

* the reader raises nothing but the toolkit's error type (:class:`abu_model.errors.AbuError`);
* a truncated recording is refused (never measured on the frames that survive), unless only
  bytes nothing refers to were cut and the frames read are exactly the original ones;
* a recording read despite flipped bytes has the original frame count and frame size;
* a tracks table read from a damaged CSV is still a valid table (finite, time increasing);
* ``abu measure-summary`` on a damaged summary exits 0 or 2, never 1 (an internal error), and
  when it exits 0 the interval it used is one the damaged file really states;
* a pulse file read despite the damage has finite, strictly increasing times, and
  ``abu identify --pulses`` on it exits 0 with a finite drive or 2 with one line.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from abu_model.errors import AbuError

SETTINGS = dict(deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.function_scoped_fixture,
                                       HealthCheck.too_slow])
N_FRAMES, H, W = 12, 24, 20
STACK = np.random.default_rng(3).integers(0, 255, size=(N_FRAMES, H, W), dtype=np.uint8)


class _Files(dict):
    def __repr__(self) -> str:  # keep hypothesis' failure report short
        return f"<{len(self)} original files>"


@pytest.fixture(scope="module")
def originals(tmp_path_factory) -> dict[str, bytes]:
    import cv2
    from measurement.imaging.frames_io import write_multipage_tiff, write_npy

    d = tmp_path_factory.mktemp("fuzz_originals")
    stack = STACK
    write_multipage_tiff(d / "ours.tif", stack)
    write_npy(d / "s.npy", stack)
    cv2.imwritemulti(str(d / "cv.tif"), list(stack))
    return _Files({name: (d / name).read_bytes() for name in ("ours.tif", "s.npy", "cv.tif")})


def _read(path: Path):
    from measurement.imaging.frames_io import read_recording
    rec = read_recording(path, mmap=False)
    return np.asarray(rec.frames)


flips = st.lists(st.tuples(st.floats(0, 1, exclude_max=True), st.integers(1, 255)),
                 min_size=1, max_size=4)


@settings(max_examples=150, **SETTINGS)
@given(name=st.sampled_from(["ours.tif", "s.npy", "cv.tif"]),
       cut=st.floats(0.0, 1.0, exclude_max=True))
def test_truncated_recording_is_refused(originals, tmp_path, name, cut):
    data = originals[name]
    path = tmp_path / name
    path.write_bytes(data[: int(cut * len(data))])
    try:
        frames = _read(path)
    except AbuError:
        return
    # Read anyway: only bytes nothing refers to were cut (e.g. padding after the last header).
    np.testing.assert_array_equal(frames, STACK)


@settings(max_examples=300, **SETTINGS)
@given(name=st.sampled_from(["ours.tif", "s.npy", "cv.tif"]), changes=flips)
def test_bit_flipped_recording_is_refused_or_keeps_its_shape(originals, tmp_path, name, changes):
    data = bytearray(originals[name])
    for where, xor in changes:
        data[int(where * len(data))] ^= xor
    path = tmp_path / name
    path.write_bytes(bytes(data))
    try:
        frames = _read(path)
    except AbuError:
        return
    assert frames.shape == (N_FRAMES, H, W) and frames.dtype == np.uint8


# ------------------------------------------------------------------------------ tracks CSV
def _tracks_text() -> str:
    t = np.arange(40) / 4500.0
    theta = -60.0 * t
    rows = ["time,x_center,y_center,x_cd,y_cd,x_ball,y_ball,lost"]
    for ti, th in zip(t, theta):
        rows.append(f"{ti!r},128.0,128.0,{128 + 95 * np.cos(th):.6f},{128 - 95 * np.sin(th):.6f},"
                    f"{128 + 40 * np.cos(th + 1):.6f},{128 - 40 * np.sin(th + 1):.6f},0")
    return "\n".join(rows) + "\n"


TRACKS = _tracks_text()


@st.composite
def mutated_text(draw, text: str) -> str:
    kind = draw(st.sampled_from(["cut", "replace", "delete", "insert", "dupline", "swapline"]))
    n = len(text)
    i = draw(st.integers(0, n - 1))
    if kind == "cut":
        return text[:i]
    if kind == "replace":
        c = draw(st.sampled_from(list("0123456789.,-e+ \n#abnNiIf\x00\"")))
        return text[:i] + c + text[i + 1:]
    if kind == "delete":
        j = draw(st.integers(i, min(n, i + 20)))
        return text[:i] + text[j:]
    if kind == "insert":
        s = draw(st.text(alphabet="0123456789.,-e+ \n#nanif", max_size=8))
        return text[:i] + s + text[i:]
    lines = text.splitlines(keepends=True)
    a = draw(st.integers(0, len(lines) - 1))
    b = draw(st.integers(0, len(lines) - 1))
    if kind == "dupline":
        return "".join(lines[: a + 1] + [lines[a]] + lines[a + 1:])
    lines[a], lines[b] = lines[b], lines[a]
    return "".join(lines)


@settings(max_examples=300, **SETTINGS)
@given(text=mutated_text(TRACKS))
def test_tracks_reader_on_mutated_files(tmp_path, text):
    from measurement.imaging.tracks_io import read_tracks_csv

    path = tmp_path / "tracks.csv"
    path.write_text(text, encoding="utf-8")
    try:
        table = read_tracks_csv(path)
    except AbuError:
        return
    assert np.isfinite(table.time).all() and np.isfinite(table.x).all()
    assert np.isfinite(table.y).all() and (np.diff(table.time) > 0).all()
    assert table.x.shape == table.y.shape == table.lost.shape == (table.time.size, 3)


def test_tracks_reader_refuses_a_row_cut_in_the_middle(tmp_path):
    from measurement.imaging.tracks_io import read_tracks_csv

    path = tmp_path / "tracks.csv"
    for cut in range(len(TRACKS) - 60, len(TRACKS) - 2, 7):  # inside the last row
        path.write_text(TRACKS[:cut], encoding="utf-8")
        with pytest.raises(AbuError):
            read_tracks_csv(path)


# ------------------------------------------------------------------------------ summaries
SUMMARY = json.dumps({"kind": "abu-measure-summary", "format_version": 1, "mu_low": 0.02955,
                      "mu_high": 0.03308, "status": "ok"}, indent=2)


@settings(max_examples=300, **SETTINGS)
@given(text=mutated_text(SUMMARY))
def test_summary_reader_on_mutated_files(tmp_path, text):
    from measurement.report.multi import read_intervals

    path = tmp_path / "summary.json"
    path.write_text(text, encoding="utf-8")
    try:
        (interval,) = read_intervals([path])
    except AbuError:
        return
    data = json.loads(text)  # accepted: it is JSON and says what it is
    assert data.get("kind", "abu-measure-summary") == "abu-measure-summary"
    lo, hi = interval["mu_low"], interval["mu_high"]
    assert 0 <= lo <= hi and not np.isnan(hi)
    assert lo == (data["mu_low"] or 0.0) and (hi == data["mu_high"] or data["mu_high"] is None)


def _exit_and_output(argv: list[str], out: Path, capsys):
    """Run the command: (exit status, captured output) after checking the failure rule: exit 0
    or 2, never a traceback; on 2 one line on stderr and nothing written at ``out``."""
    from abu.cli.main import main

    try:
        code = main(argv)
    except SystemExit as exc:
        code = exc.code
    captured = capsys.readouterr()
    assert code in (0, 2), captured.err
    assert "Traceback" not in captured.err
    if code == 2:
        assert len(captured.err.strip().splitlines()) == 1 and not out.exists()
    return code, captured


@settings(max_examples=25, **SETTINGS)
@given(text=mutated_text(SUMMARY))
def test_measure_summary_command_on_mutated_files(tmp_path_factory, text, capsys):
    d = tmp_path_factory.mktemp("fuzz_summary")
    path = d / "summary.json"
    path.write_text(text, encoding="utf-8")
    out = d / "out"
    code, captured = _exit_and_output(["measure-summary", str(path), "--out", str(out),
                                       "--json"], out, capsys)
    if code == 0:
        data = json.loads(text)
        result = json.loads(captured.out)
        assert result["union_hull"][0] == pytest.approx(data["mu_low"] or 0.0)


# ------------------------------------------------------------------- identify --pulses
def _pulses_text() -> str:
    """Pulse times [s] of a 4-pulse/rev sensor on a speed step 5 -> 20 Hz at 0.1 s behind the
    twin's loop (zeta 0.7, omega_n 12 rad/s, 20 ms lag), timer quantum 20 us."""
    from harness.planning.loop_response import Setpoints, response

    sp = Setpoints((0.1,), (5 * 2 * np.pi, 20 * 2 * np.pi))
    t = np.linspace(0.0, 1.3, 20001)
    angle = response(sp, t, 0.7, 12.0, 0.02).theta
    angle = angle - angle[0]
    k = np.arange(1, int(angle[-1] / (np.pi / 2)))
    tp = np.round(np.interp(k * np.pi / 2, angle, t) / 20e-6) * 20e-6
    return "time_s\n" + "".join(f"{float(v)!r}\n" for v in tp)


PULSES = _pulses_text()
SETPOINTS = f"time_s,omega_ref_rad_s\n0.0,{5 * 2 * np.pi!r}\n0.1,{20 * 2 * np.pi!r}\n"


def test_the_undamaged_pulse_file_identifies_its_loop(tmp_path, capsys):
    """The fuzz tests below start from a file that works (else they would test refusals only)."""
    from abu.cli.main import main

    (tmp_path / "pulses.csv").write_text(PULSES, encoding="utf-8")
    (tmp_path / "setpoints.csv").write_text(SETPOINTS, encoding="utf-8")
    assert main(["identify", "--pulses", str(tmp_path / "pulses.csv"), "--pulses-per-rev", "4",
                 "--setpoints", str(tmp_path / "setpoints.csv"), "--out", str(tmp_path / "o"),
                 "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["omega_n_rad_s"] == pytest.approx(12.0, rel=0.05)


@settings(max_examples=300, **SETTINGS)
@given(text=mutated_text(PULSES))
def test_pulses_reader_on_mutated_files(tmp_path, text):
    from harness.planning.record_io import read_pulses

    path = tmp_path / "pulses.csv"
    path.write_text(text, encoding="utf-8")
    try:
        record = read_pulses(path, 4)
    except AbuError:
        return
    assert np.isfinite(record.t).all() and (np.diff(record.t) > 0).all()
    assert record.y.tolist() == list(range(record.t.size)) and record.pulses_per_rev == 4


@settings(max_examples=30, **SETTINGS)
@given(text=mutated_text(PULSES))
def test_identify_pulses_command_on_mutated_files(tmp_path_factory, text, capsys):
    """``abu identify --pulses`` on a damaged pulse file: exit 0 with a drive whose parameters
    are finite and positive, or exit 2 with one line and nothing written; never a traceback."""
    from controller.drive import load_drive

    d = tmp_path_factory.mktemp("fuzz_pulses")
    (d / "pulses.csv").write_text(text, encoding="utf-8")
    (d / "setpoints.csv").write_text(SETPOINTS, encoding="utf-8")
    out = d / "out"
    code, _ = _exit_and_output(["identify", "--pulses", str(d / "pulses.csv"),
                                "--pulses-per-rev", "4", "--setpoints", str(d / "setpoints.csv"),
                                "--out", str(out), "--json"], out, capsys)
    if code == 0:
        drive = load_drive(out / "drive.json")
        for value in (drive.zeta, drive.omega_n, drive.tau_motor):
            assert np.isfinite(value) and value >= 0.0
        assert drive.zeta > 0 and drive.omega_n > 0
