"""Tracks CSV input/output and the measurement commands (track, measure) with their errors."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from measurement.imaging import tracks_io
from abu.cli.main import main
from measurement.imaging.tracks_io import (LostMarkerError, TracksFileError, fill_lost, read_tracks_csv,
                                   write_tracks_csv)
from synthetic_tracks import measured_pixels, simulate, to_pixels

HEADER = "time,x_center,y_center,x_cd,y_cd,x_ball,y_ball"


@pytest.fixture(scope="module")
def record():
    return simulate(0.02, "steps", n=1500)


@pytest.fixture(scope="module")
def tracks_csv(record, tmp_path_factory):
    x, y = measured_pixels(record, sigma_px=0.02, harmonic_px=0.4, seed=11)
    path = tmp_path_factory.mktemp("tracks") / "input.csv"
    lines = [HEADER] + [",".join(f"{v:.6f}" for v in (t, *np.ravel(np.c_[xi, yi])))
                        for t, xi, yi in zip(record.time, x, y)]
    path.write_text("\n".join(lines) + "\n")
    return path


def small_csv(tmp_path, rows, header=HEADER, name="t.csv", prefix=""):
    p = tmp_path / name
    p.write_text(prefix + header + "\n" + "\n".join(rows) + "\n")
    return p


def good_rows(n=30):
    return [f"{i / 4500:.8f},128,128,{128 + 90 * math.cos(-0.01 * i):.4f},"
            f"{128 - 90 * math.sin(-0.01 * i):.4f},170,128" for i in range(n)]


# ------------------------------------------------------------------------------ tracks_io

def test_tracks_csv_round_trip(tmp_path, record):
    x, y = to_pixels(record.theta, record.beta)
    lost = np.zeros((record.time.size, 3), dtype=bool)
    lost[10, 2] = True
    theta, beta = write_tracks_csv(tmp_path / "tracks.csv", record.time, x, y, lost)
    np.testing.assert_allclose(theta, record.theta, atol=1e-9)
    np.testing.assert_allclose(beta, record.beta, atol=1e-9)
    back = read_tracks_csv(tmp_path / "tracks.csv")
    np.testing.assert_array_equal(back.time, record.time)
    np.testing.assert_array_equal(back.x, x)
    np.testing.assert_array_equal(back.lost, lost)
    text = (tmp_path / "tracks.csv").read_text().splitlines()
    # plain CSV (issue 7): no comment line, units in the column names
    assert text[0] == ("time_s,theta_rad,beta_rad,x_center_px,y_center_px,x_cd_px,y_cd_px,"
                       "x_ball_px,y_ball_px,lost")


@pytest.mark.parametrize("mutate, match", [
    (lambda r: r.__setitem__(4, r[4].replace(",170,", ",nan,")),
     r"data row 5, line 8, column 'x_ball': non-finite"),
    (lambda r: r.__setitem__(2, r[2].replace(",128,", ",abc,", 1)),
     r"data row 3, line 6, column 'x_center': non-numeric value 'abc'"),
    (lambda r: r.__setitem__(7, r[7].rsplit(",", 1)[0]),
     r"data row 8, line 11, column 'y_ball': empty or missing"),
    (lambda r: r.__setitem__(9, r[8]),
     r"data row 10, line 13, column 'time': time .* (repeats|goes back from) .* expected strictly increasing times"),
])
def test_tracks_csv_errors_name_row_line_and_column(tmp_path, mutate, match):
    rows = good_rows()
    mutate(rows)
    # A comment line and a blank line shift the line numbers but not the data rows.
    p = small_csv(tmp_path, rows, prefix="# tracked by hand\n\n")
    with pytest.raises(TracksFileError, match=match) as info:
        read_tracks_csv(p)
    assert str(p) in str(info.value)


def test_tracks_csv_missing_column_and_too_few_rows(tmp_path):
    p = small_csv(tmp_path, [r.rsplit(",", 1)[0] for r in good_rows()],
                  header="time,x_center,y_center,x_cd,y_cd,x_ball")
    with pytest.raises(TracksFileError, match=r"line 1, column 'y_ball': missing column"):
        read_tracks_csv(p)
    p = small_csv(tmp_path, good_rows(5), name="short.csv")
    with pytest.raises(TracksFileError, match="5 data rows; the analysis needs at least 20"):
        read_tracks_csv(p)
    with pytest.raises(TracksFileError, match="file not found"):
        read_tracks_csv(tmp_path / "nope.csv")


def test_fill_lost_interpolates_short_gaps_and_rejects_long_ones():
    t = np.arange(400) / 4500
    vals = np.stack([t * 0 + 1, 2 + 3 * t, 5 - t], axis=1)
    lost = np.zeros((400, 3), dtype=bool)
    lost[40:43, 1] = True
    noisy = vals.copy()
    noisy[lost] = np.nan
    np.testing.assert_allclose(fill_lost(t, noisy, lost), vals)
    lost[40:50, 2] = True
    with pytest.raises(LostMarkerError, match=r"'ball' lost in frames 40-49"):
        fill_lost(t, noisy, lost)
    lost = np.zeros((400, 3), dtype=bool)
    lost[0, 0] = True
    with pytest.raises(LostMarkerError, match=r"'center' lost in frames 0-0 \(up to the first"):
        fill_lost(t, vals, lost)
    lost = np.zeros((400, 3), dtype=bool)
    lost[10:400:20, 1] = True        # isolated frames, but 5 % of the record
    with pytest.raises(LostMarkerError, match=r"'cd' lost in 20 of 400 frames"):
        fill_lost(t, vals, lost)


# ------------------------------------------------------------------------------ measure --tracks

def test_measure_tracks_csv_contains_the_true_mu(tracks_csv, record, tmp_path, capsys):
    out = tmp_path / "out"
    code = main(["measure", str(tracks_csv), "--tracks", "--out", str(out), "--json",
                 "--mc-draws", "3", "--quiet"])
    assert code == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary == json.loads((out / "summary.json").read_text())
    assert summary["mu_low"] <= record.mu <= summary["mu_high"]
    assert summary["monte_carlo"]["draws"] == 3
    assert summary["fps_hz"] == pytest.approx(4500.0)
    for name in ("tracks.csv", "kinematics.csv", "beta.png", "kinematics.png"):
        assert (out / name).stat().st_size > 0, name
    # The written tracks are the input's, with the angles added.
    back = read_tracks_csv(out / "tracks.csv")
    src = read_tracks_csv(tracks_csv)
    np.testing.assert_allclose(back.x, src.x)
    kin = (out / "kinematics.csv").read_text().splitlines()
    assert kin[0].startswith("time_s,theta_rad,beta_rad")   # plain CSV: header first


def test_measure_prints_a_readable_result(tracks_csv, tmp_path, capsys):
    assert main(["measure", str(tracks_csv), "--tracks", "--out", str(tmp_path / "o"),
                 "--mc-draws", "0", "--no-plots", "--quiet"]) == 0
    text = capsys.readouterr().out
    assert text.startswith("mu in [")
    assert "11.6 %" in text          # the report's worst case, 3 % / 5 %


@pytest.mark.parametrize("args, match", [
    (["--fps", "-5"], "'--fps' = -5.0"),
    (["--fps", "1000"], "'--fps' = 1000.0: expected the frame rate of the tracks file"),
    (["--l", "0"], "'--l' = 0.0"),
    (["--mc-draws", "-1"], "'--mc-draws' = -1"),
    (["--k-sigma", "nan"], "'--k-sigma'"),
    (["--max-fit-samples", "100"], "'--max-fit-samples' = 100: expected an integer in [256, 16384]"),
])
def test_measure_bad_options_exit_2(tracks_csv, tmp_path, capsys, args, match):
    out = tmp_path / "o"
    assert main(["measure", str(tracks_csv), "--tracks", "--out", str(out), *args]) == 2
    assert match in capsys.readouterr().err
    assert not out.exists()


def test_a_tracks_csv_without_tracks_is_named_and_the_option_given(tracks_csv, tmp_path, capsys):
    """A tracks CSV given as a recording (no --tracks), to abu measure and abu track: refused
    by the recording reader, naming the file and the option (it said only that no reader
    could decode it)."""
    for command in ("measure", "track"):
        out = tmp_path / command
        assert main([command, str(tracks_csv), "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert f"'{tracks_csv}' is a text file, not a recording" in err, err
        assert "abu measure --tracks" in err and "Traceback" not in err
        assert not out.exists()


def test_measure_bad_tracks_file_exits_2_and_writes_nothing(tmp_path, capsys):
    rows = good_rows()
    rows[3] = rows[3].replace(",128,", ",,", 1)
    p = small_csv(tmp_path, rows)
    out = tmp_path / "o"
    assert main(["measure", str(p), "--tracks", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "data row 4, line 5, column 'x_center'" in err
    assert not out.exists()


def test_lost_marker_in_tracks_exits_2(tmp_path, capsys, record):
    x, y = to_pixels(record.theta, record.beta)
    lost = np.zeros((record.time.size, 3), dtype=bool)
    lost[200:220, 1] = True
    text = tracks_io.format_tracks_csv(record.time, record.theta, record.beta, x, y, lost)
    p = tmp_path / "lost.csv"
    p.write_text(text)
    assert main(["measure", str(p), "--tracks", "--out", str(tmp_path / "o")]) == 2
    assert "'cd' lost in frames 200-219" in capsys.readouterr().err


# ------------------------------------------------------------------------------ frames input

def rendered_stack(tmp_path, n=60, hide_ball=None):
    from twin import render
    geo = render.CameraGeometry()
    theta = -2 * math.pi * 9 * np.arange(n) / 4500
    beta = np.full(n, 0.6)
    c, cd, ball = geo.marker_positions(theta, beta)
    frames = render.render_frames(c, cd, ball, render.RenderSettings(), seed=1)
    if hide_ball is not None:
        frames[hide_ball[0]:hide_ball[1]] = render.render_frames(
            c[hide_ball[0]:hide_ball[1]], cd[hide_ball[0]:hide_ball[1]],
            ball[hide_ball[0]:hide_ball[1]],
            render.RenderSettings().with_(ball=render.MarkerStyle(5.0, 60.0)), seed=2)
    path = tmp_path / "rec.npy"
    np.save(path, frames)
    return path, theta, beta, (c, cd, ball)


def test_track_command_finds_markers_and_writes_tracks(tmp_path, capsys):
    path, theta, beta, _ = rendered_stack(tmp_path)
    out = tmp_path / "tr"
    assert main(["track", str(path), "--out", str(out), "--fps", "4500"]) == 0
    err = capsys.readouterr().err
    assert "centre (" in err and "ball (" in err and "--seeds" in err
    tr = read_tracks_csv(out / "tracks.csv")
    th, be = tracks_io.angles_from_pixels(tr.x, tr.y)
    # The ball's apparent centre is shifted by the lighting (0.5 px): beta is off by ~0.013 rad.
    assert np.abs(th - theta).max() < 2e-3
    assert np.abs(be - beta).max() < 0.03
    info = json.loads((out / "tracking.json").read_text())
    assert info["frames"] == 60 and info["lost_frames"] == {"center": 0, "cd": 0, "ball": 0}


def test_track_with_malformed_seeds_exits_2(tmp_path, capsys):
    path, *_ = rendered_stack(tmp_path, n=25)
    out = tmp_path / "tr"
    assert main(["track", str(path), "--out", str(out), "--fps", "4500", "--seeds", "1,2;3"]) == 2
    assert "seeds" in capsys.readouterr().err
    assert not out.exists()


def test_track_with_seeds_outside_the_frame_exits_2(tmp_path, capsys):
    path, *_ = rendered_stack(tmp_path, n=25)
    assert main(["track", str(path), "--out", str(tmp_path / "tr"), "--fps", "4500",
                 "--seeds", "128,128;300,40;150,120"]) == 2
    assert "position 2 is outside" in capsys.readouterr().err


def test_track_lost_marker_names_the_frames(tmp_path, capsys):
    path, _, _, (c, cd, ball) = rendered_stack(tmp_path, n=60, hide_ball=(20, 35))
    seeds = f"{c[0, 0]},{c[0, 1]};{cd[0, 0]},{cd[0, 1]};{ball[0, 0]},{ball[0, 1]}"
    out = tmp_path / "tr"
    assert main(["track", str(path), "--out", str(out), "--fps", "4500", "--seeds", seeds]) == 2
    err = capsys.readouterr().err
    # The tracker may or may not find the ball again after frame 34; either way frame 20 is named.
    assert "'ball' lost in frames 20-" in err
    assert not out.exists()


def test_unreadable_frame_in_a_folder_exits_2(tmp_path, capsys):
    import cv2
    folder = tmp_path / "frames"
    folder.mkdir()
    for i in range(3):
        cv2.imwrite(str(folder / f"f{i:03d}.png"), np.full((32, 32), 50, np.uint8))
    (folder / "f003.png").write_bytes(b"not a png")
    out = tmp_path / "o"
    assert main(["measure", str(folder), "--out", str(out), "--seeds", "5,5;10,10;20,20"]) == 2
    assert "f003.png" in capsys.readouterr().err
    assert not out.exists()


def test_measure_imports_no_heavy_library(tracks_csv, tmp_path):
    """The 2 s budget of `abu measure` (issue 7): SciPy (scipy.optimize alone cost 0.33 s
    through the lower bound's root finder), fmpy, Dask and python-control are never imported,
    matplotlib only when plotting; nor the twin and the harness, which only other commands'
    parsers need (issue 20)."""
    import subprocess
    import sys
    heavy = ("scipy", "matplotlib", "fmpy", "dask", "control", "pandas", "twin", "harness")
    code = ("import json, sys; from abu.cli.main import main; "
            f"rc = main(['measure', {str(tracks_csv)!r}, '--tracks', '--out', "
            f"{str(tmp_path / 'o')!r}, '--quiet', '--no-plots']); "
            f"print(json.dumps([rc] + sorted(m for m in {heavy!r} if m in sys.modules)))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.strip().splitlines()[-1]
    assert json.loads(out) == [0]


def _options(parser, command: str) -> dict:
    """Option string -> (dest, default, nargs, choices) of ``command``'s subparser."""
    import argparse
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return {s: (a.dest, repr(a.default), a.nargs, a.choices)
            for a in sub.choices[command]._actions for s in a.option_strings or [a.dest]}


def test_a_named_command_builds_only_its_own_parser_and_the_same_one():
    """`abu CMD` registers only the module of CMD (the others import the twin and the harness:
    ~40 ms of `abu measure`'s budget): the map covers every command of the full parser, and
    each command's options, defaults and choices are those of the full parser."""
    import argparse
    from abu.cli.main import COMMAND_MODULE, _command_of, build_parser
    full = build_parser()
    sub = next(a for a in full._actions if isinstance(a, argparse._SubParsersAction))
    assert set(sub.choices) == set(COMMAND_MODULE)
    for command in COMMAND_MODULE:
        assert _options(build_parser(command), command) == _options(full, command), command
    assert _command_of(["--debug", "measure", "x", "--out", "y"]) == "measure"
    assert _command_of(["--version"]) is None
    assert _command_of(["-h", "measure"]) is None          # the top-level help: every command
    assert _command_of(["measure", "-h"]) == "measure"
