"""A table of bad inputs to every ``abu`` command (issue 11).

Each case asserts: exit status 2, exactly one line on stderr that names the option (as typed)
or the file, no output file or folder left behind (nor a temporary or lock file), within 10 s.
Most cases run in-process through ``abu.cli.main.main`` (fast); a few run the real ``abu``
entry point in a subprocess to prove the exit status.
"""
from __future__ import annotations

import fcntl
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from abu.cli.main import main

from synthetic_tracks import measured_pixels, simulate

HEADER = "time,x_center,y_center,x_cd,y_cd,x_ball,y_ball"
LIMIT_S = 10.0


# ------------------------------------------------------------------------------ fixtures
def _write_tracks(path: Path, time_s, x, y, *, time_scale: float = 1.0, swap: bool = False,
                  still: bool = False) -> Path:
    x = np.array(x, dtype=float)
    y = np.array(y, dtype=float)
    if swap:
        x[:, [1, 2]] = x[:, [2, 1]]
        y[:, [1, 2]] = y[:, [2, 1]]
    if still:
        x[:] = x[0]
        y[:] = y[0]
    lines = [HEADER] + [",".join(f"{v:.6f}" for v in (t * time_scale, *np.ravel(np.c_[xi, yi])))
                        for t, xi, yi in zip(time_s, x, y)]
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict[str, Path]:
    """Bad (and a few good) input files, made once."""
    import cv2
    from measurement.imaging.frames_io import write_multipage_tiff

    d = tmp_path_factory.mktemp("bad_inputs_files")
    rec = simulate(0.02, "steps", n=1500)
    x, y = measured_pixels(rec, sigma_px=0.02, harmonic_px=0.4, seed=11)
    f = {"tracks": _write_tracks(d / "tracks.csv", rec.time, x, y),
         "tracks_ms": _write_tracks(d / "tracks_ms.csv", rec.time, x, y, time_scale=1e3),
         "tracks_swap": _write_tracks(d / "tracks_swap.csv", rec.time, x, y, swap=True),
         "tracks_still": _write_tracks(d / "tracks_still.csv", rec.time, x, y, still=True)}
    rows = open(f["tracks"]).read().splitlines()
    f["tracks_short"] = d / "short.csv"
    f["tracks_short"].write_text("\n".join(rows[:10]) + "\n")
    f["tracks_nocol"] = d / "nocol.csv"
    f["tracks_nocol"].write_text("\n".join(r.rsplit(",", 1)[0] for r in rows) + "\n")
    f["tracks_text"] = d / "text.csv"
    f["tracks_text"].write_text("\n".join(rows[:30] + [rows[30].replace(",", ",abc,", 1)]
                                          + rows[31:]) + "\n")
    f["tracks_nan"] = d / "nan.csv"
    f["tracks_nan"].write_text("\n".join(rows[:40] + ["nan" + rows[40][rows[40].index(","):]]
                                         + rows[41:]) + "\n")
    f["tracks_back"] = d / "back.csv"
    f["tracks_back"].write_text("\n".join(rows[:50] + [rows[48]] + rows[51:]) + "\n")
    f["empty"] = d / "empty.csv"
    f["empty"].write_text("")
    f["binary"] = d / "binary.csv"
    f["binary"].write_bytes(bytes(range(256)) * 8)
    # recordings
    rng = np.random.default_rng(0)
    stack = rng.integers(0, 255, size=(40, 64, 64), dtype=np.uint8)
    tif = write_multipage_tiff(d / "ours.tif", stack)
    f["tif_half"] = d / "ours_half.tif"
    f["tif_half"].write_bytes(tif.read_bytes()[: tif.stat().st_size // 2])
    cv2.imwritemulti(str(d / "cv.tif"), list(stack))
    data = (d / "cv.tif").read_bytes()
    f["cvtif_half"] = d / "cv_half.tif"
    f["cvtif_half"].write_bytes(data[: len(data) // 2])
    f["npy_nh"] = d / "nh.npy"
    np.save(f["npy_nh"], stack[:, :, 0].copy())
    f["npy_float"] = d / "float.npy"
    np.save(f["npy_float"], stack.astype(np.float32))
    f["npy_half"] = d / "half.npy"
    np.save(d / "full.npy", stack)
    f["npy_half"].write_bytes((d / "full.npy").read_bytes()[:40000])
    f["npy"] = d / "full.npy"
    f["text_rec"] = d / "notes.txt"
    f["text_rec"].write_text("not a recording\n")
    f["empty_dir"] = d / "empty_dir"
    f["empty_dir"].mkdir()
    # summaries
    f["sim_summary"] = d / "sim_summary.json"
    f["sim_summary"].write_text(json.dumps({"kind": "abu-simulate-summary", "format_version": 1,
                                            "mu_low": 0.0027, "mu_high": 0.0033}))
    f["sim_legacy"] = d / "sim_legacy.json"
    f["sim_legacy"].write_text(json.dumps({"experiment": {}, "switches": [], "mu_low": 0.0027,
                                           "mu_high": 0.0033}))
    f["other_kind"] = d / "other.json"
    f["other_kind"].write_text(json.dumps({"kind": "abu-render-meta", "mu_low": 0.02,
                                           "mu_high": 0.03}))
    f["future"] = d / "future.json"
    f["future"].write_text(json.dumps({"kind": "abu-measure-summary", "format_version": 99,
                                       "mu_low": 0.02, "mu_high": 0.03}))
    f["good_summary"] = d / "good.json"
    f["good_summary"].write_text(json.dumps({"kind": "abu-measure-summary", "format_version": 1,
                                             "mu_low": 0.02, "mu_high": 0.03}))
    f["inverted"] = d / "inverted.json"
    f["inverted"].write_text(json.dumps({"mu_low": 0.04, "mu_high": 0.03}))
    f["negative"] = d / "negative.json"
    f["negative"].write_text(json.dumps({"mu_low": -0.01, "mu_high": 0.03}))
    f["listjson"] = d / "list.json"
    f["listjson"].write_text("[0.02, 0.03]")
    f["notjson"] = d / "not.json"
    f["notjson"].write_text("{mu_low: 0.02")
    f["nobounds"] = d / "nobounds.json"
    f["nobounds"].write_text(json.dumps({"mu_low": None, "mu_high": None}))
    f["strbound"] = d / "strbound.json"
    f["strbound"].write_text(json.dumps({"mu_low": "abc", "mu_high": 0.03}))
    f["csv_bad"] = d / "intervals.csv"
    f["csv_bad"].write_text("a,b\n1,2\n")
    # FMU folders
    f["fmu_corrupt"] = d / "fmus_corrupt"
    f["fmu_corrupt"].mkdir()
    (f["fmu_corrupt"] / "AbuBall.fmu").write_bytes(b"PK\x03\x04 this is not a zip")
    f["fmu_nomd"] = d / "fmus_nomd"
    f["fmu_nomd"].mkdir()
    import zipfile
    with zipfile.ZipFile(f["fmu_nomd"] / "Staircase.fmu", "w") as z:
        z.writestr("readme.txt", "no model description")
    f["afile"] = d / "a_file"
    f["afile"].write_text("x")
    return f


# ------------------------------------------------------------------------------ the table
# (argv with {placeholders}, the text stderr must contain). {out} is a fresh output folder,
# {csv} a fresh output file; other placeholders are the fixtures' files.
S = ["simulate", "--out", "{out}"]
R = ["simulate", "--motion", "ramp", "--out", "{out}"]
T = ["table41", "--mu", "0.00275"]
W = ["sweep", "--mu", "0.01", "--omega0-hz", "-17", "--out", "{csv}"]
MT = ["measure", "--tracks", "{tracks}", "--out", "{out}", "--no-plots", "--mc-draws", "0"]
MS = ["measure-summary", "{good_summary}", "--out", "{out}"]

CASES: list[tuple[list[str], str]] = []


def case(argv: list[str], needle: str) -> None:
    CASES.append((argv, needle))


# simulate, staircase: every numeric option, non-finite, out of range, beyond the limits
for opt, values in {
    "--omega0-hz": ["nan", "inf", "-inf", "0", "1e6", "-1e6", "2000"],
    "--omega-end-hz": ["nan", "-inf", "-1e9", "-17.5", "1e4"],
    "--t0": ["nan", "inf", "1e9", "-1e9"],
    "--te": ["0", "-1", "nan", "1e7", "inf"],
    "--t-end": ["nan", "-1", "1e9", "0.2"],
    "--step-hz": ["0", "-1", "nan", "1e-9", "inf"],
    "--comm-step": ["0", "-1e-3", "nan", "1e-9", "10", "0.3", "inf"],
    "--tol": ["0", "-1e-5", "nan", "inf", "1e-12", "1", "1e300"],
    "--zeta": ["0", "-1", "nan", "1e6", "inf"],
    "--omega-n": ["0", "-2", "nan", "1e6", "inf"],
    "--mu": ["0", "-0.1", "nan", "inf", "5"],
    "--mu-d": ["nan", "-0.1", "0.01"],
    "--m": ["-inf", "0", "-1", "nan"],
    "--d": ["0", "0.1", "nan", "-1"],
    "--l": ["0", "-1", "nan"],
    "--j-abu": ["0", "-1", "nan"],
    "--tau-motor": ["-1", "nan", "10"],
    "--beta0": ["nan", "inf", "1e300"],
}.items():
    for v in values:
        case(S + [opt, v], opt)
case(S + ["--omega0-hz=-1e6"], "--omega0-hz")
case(S + ["--omega-end-hz=-1e9"], "--omega-end-hz")
case(S + ["--t0", "1", "--t-end", "0.5"], "--t-end")
case(S + ["--theta-ref", "bogus"], "--theta-ref")
case(S + ["--rounding", "up"], "--rounding")
case(S + ["--motion", "spiral"], "--motion")
case(S + ["--mu", "abc"], "--mu")
case(S + ["--omega0-hz"], "--omega0-hz")
case(S + ["--no-such-option"], "--no-such-option")
case(S + ["--fmu-dir", "{fmu_corrupt}"], "--fmu-dir")
case(S + ["--fmu-dir", "{fmu_nomd}"], "--fmu-dir")
case(S + ["--fmu-dir", "{afile}"], "--fmu-dir")
# simulate, ramp
for opt, values in {"--jerk": ["1e11", "0", "-1", "nan", "inf"],
                    "--t-end": ["1e6", "0", "-1", "nan"],
                    "--mu": ["0", "nan"], "--omega0-hz": ["0", "-1e6"],
                    "--comm-step": ["1e-9", "0"]}.items():
    for v in values:
        case(R + [opt, v], opt)
# table41
for opt, values in {"--mu": ["-1", "0", "nan", "inf", "1e-12", "5"],
                    "--step-hz": ["0", "1e-9", "1e6", "nan", "-1"],
                    "--t-step": ["1e9", "nan", "inf"]}.items():
    for v in values:
        base = ["table41", "--theta-ref", "thesis"] + ([] if opt == "--mu" else ["--mu", "0.00275"])
        case(base + [opt, v], opt)
case(T + ["--fmu-dir", "{fmu_corrupt}"], "--fmu-dir")
case(["table41"], "--mu")
# sweep
for opt, values in {"--span-hz": ["1e7", "0.5", "nan"], "--workers": ["0", "1000"],
                    "--te": ["0", "1e7"], "--zeta": ["1e6"], "--omega-n": ["1e6"]}.items():
    for v in values:
        case(W + [opt, v], opt)
case(["sweep", "--mu", "0", "--omega0-hz", "-17", "--out", "{csv}"], "--mu")
case(["sweep", "--mu", "nan", "--omega0-hz", "-17", "--out", "{csv}"], "--mu")
case(["sweep", "--mu", "0.01", "--omega0-hz", "0", "--out", "{csv}"], "--omega0-hz")
case(["sweep", "--mu", "0.01", "--omega0-hz", "1e6", "--out", "{csv}"], "--omega0-hz")
case(["sweep", "--mu", "0.01", "--omega0-hz", "-17", "--out", "{afile}/x.csv"], "a_file")
case(W + ["--fmu-dir", "{fmu_corrupt}"], "--fmu-dir")
# build-fmus
case(["build-fmus", "--out", "{afile}"], "--out")
case(["build-fmus", "--out", "{afile}/sub"], "a_file")
# render
for opt, values in {"--frames": ["100000000", "0", "1e8"], "--fps": ["1e-3", "nan", "0", "1e9"],
                    "--mu": ["-1", "nan", "0", "1e300"], "--te": ["0", "nan", "1e300"],
                    "--t0": ["-1e300"], "--seed": ["-1"], "--noise": ["1e300", "-1"],
                    "--gradient": ["1e300"], "--ball-shift-px": ["1e300"],
                    "--pixel-size": ["1e300", "0"], "--exposure-fraction": ["2"],
                    "--beta0": ["1e300"], "--omega0-hz": ["nan", "-1e6"]}.items():
    for v in values:
        case(["render", "--out", "{out}", opt, v], opt)
case(["render", "--out", "{afile}"], "--out")
# track: recordings
for name in ("tif_half", "cvtif_half", "npy_nh", "npy_float", "npy_half", "text_rec",
             "empty_dir"):
    case(["track", "{%s}" % name, "--out", "{out}"], "{%s}" % name)
case(["track", "{missing}", "--out", "{out}"], "{missing}")
for opt, values in {"--window": ["3", "100000"], "--fps": ["0", "nan", "-1", "1e9"],
                    "--seeds": ["1,2;3", "abc", "1000,1000;1,1;2,2"],
                    "--method": ["bogus"]}.items():
    for v in values:
        rate = [] if opt == "--fps" else ["--fps", "4500"]   # a .npy states no frame rate
        case(["track", "{npy}", "--out", "{out}", *rate, opt, v], opt)
case(["track", "{npy}", "--out", "{out}"], "--fps")   # ... and needs one
case(["measure", "{npy}", "--out", "{out}"], "--fps")
# measure: the measurement cases of the issue and more
case(["measure", "--tracks", "{tracks_ms}", "--out", "{out}"], "tracks_ms.csv")
case(["measure", "--tracks", "{tracks_still}", "--out", "{out}"], "tracks_still.csv")
case(["measure", "--tracks", "{tracks_swap}", "--out", "{out}"], "tracks_swap.csv")
case(["measure", "{npy}", "--out", "{out}", "--fps", "45"], "--fps")
case(MT + ["--estimator", "report", "--poly-degree=-1"], "--poly-degree")
case(MT + ["--estimator", "report", "--poly-degree", "100"], "--poly-degree")
for opt, values in {"--trim-s": ["10", "-1", "nan"], "--sg-window-s": ["0", "nan", "5", "-0.02"],
                    "--k-sigma": ["0", "nan", "1e9"], "--mc-draws": ["-1", "10000000"],
                    "--l": ["0", "nan", "-1", "1e300"], "--d": ["0", "1", "nan", "1e300"],
                    "--seed": ["-1"], "--max-fit-samples": ["10", "100000"],
                    "--line-time": ["nan", "0.01", "-1"],
                    "--fps": ["1e9", "nan"], "--estimator": ["magic"], "--lower": ["x"]}.items():
    for v in values:
        case(MT + [opt, v], opt)
for name in ("tracks_short", "tracks_nocol", "tracks_text", "tracks_nan", "tracks_back", "empty",
             "binary", "empty_dir"):
    case(["measure", "--tracks", "{%s}" % name, "--out", "{out}"], "{%s}" % name)
case(["measure", "--tracks", "{missing}", "--out", "{out}"], "{missing}")
case(["measure", "{tif_half}", "--out", "{out}"], "{tif_half}")
case(["measure", "{npy_nh}", "--out", "{out}"], "{npy_nh}")
# measure-summary
for name in ("sim_summary", "sim_legacy", "other_kind", "future", "inverted", "negative",
             "listjson", "notjson", "nobounds", "strbound", "csv_bad", "missing"):
    case(["measure-summary", "{good_summary}", "{%s}" % name, "--out", "{out}"], "{%s}" % name)
for v in ("1", "0", "-5", "100000000", "1e8"):
    case(MS + ["--bins", v], "--bins")
# outputs: existing results, a file in the way, the input inside --out, a locked folder
case(["simulate", "--out", "{nonempty}"], "--overwrite")
case(["measure", "--tracks", "{tracks}", "--out", "{nonempty}"], "--overwrite")
case(["measure-summary", "{good_summary}", "--out", "{nonempty}"], "--overwrite")
case(["render", "--out", "{nonempty}"], "--overwrite")
case(["track", "{npy}", "--out", "{nonempty}"], "--overwrite")
case(["build-fmus", "--out", "{nonempty}"], "--overwrite")
case(["sweep", "--mu", "0.01", "--omega0-hz", "-17", "--out", "{existing_csv}"], "--overwrite")
case(["measure", "--tracks", "{tracks}", "--out", "{afile}"], "--out")
case(["measure", "{files_dir}", "--out", "{files_dir}", "--overwrite"], "--out")
case(["simulate", "--out", "{locked}"], "another abu run")
case(["render", "--out", "{locked}"], "another abu run")
case(["measure", "--tracks", "{tracks}", "--out", "{locked}"], "another abu run")
case(["sweep", "--mu", "0.01", "--omega0-hz", "-17", "--out", "{locked_csv}"], "another abu run")
case(["build-fmus", "--out", "{locked}"], "another abu run")
# empty values (an empty path would be the current folder or nothing at all)
case(["simulate", "--out", ""], "--out")
case(["simulate", "--fmu-dir", "", "--out", "{out}"], "--fmu-dir")
case(["track", "", "--out", "{out}"], "INPUT")
case(["measure-summary", "", "--out", "{out}"], "SUMMARIES")
case(["measure-summary", "/dev/null", "--out", "{out}"], "/dev/null")
case(["measure", "--tracks", "{tracks}", "--out", "{out}", "--seeds", ""], "--seeds")
# top level
case(["no-such-command"], "no-such-command")
case([], "COMMAND")


def test_the_table_is_large_enough():
    print(f"\n{len(CASES)} bad-input cases")
    assert len(CASES) >= 150
    assert len({tuple(a) for a, _ in CASES}) == len(CASES)


def _fill(items: list[str], mapping: dict[str, str]) -> list[str]:
    return [s.format(**mapping) for s in items]


def _listing(folder: Path) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob("*")}


@pytest.mark.parametrize("argv,needle", CASES, ids=[" ".join(a)[:80] for a, _ in CASES])
def test_bad_input(argv, needle, files, tmp_path, capsys):
    work = tmp_path / "work"
    work.mkdir()
    nonempty = work / "previous"
    nonempty.mkdir()
    (nonempty / "result.csv").write_text("a previous run's result\n")
    existing_csv = work / "previous.csv"
    existing_csv.write_text("previous\n")
    locked = work / "busy"
    locked_csv = work / "busy.csv"
    mapping = {k: str(v) for k, v in files.items()}
    mapping.update(out=str(work / "out"), csv=str(work / "sweep.csv"),
                   missing=str(work / "missing.csv"), nonempty=str(nonempty),
                   existing_csv=str(existing_csv), locked=str(locked),
                   locked_csv=str(locked_csv),
                   files_dir=str(files["tracks"].parent))
    args = _fill(argv, mapping)
    needle = needle.format(**{k: Path(v).name for k, v in mapping.items()})
    before = _listing(work)
    files_before = _listing(files["tracks"].parent)
    lock_fd = None
    held = [t for t in ("{locked}", "{locked_csv}") if t in argv]
    if held:  # another run holds the lock (flock conflicts between open files)
        name = Path(held[0].format(**mapping)).name
        lock_fd = os.open(work / f".{name}.lock", os.O_RDWR | os.O_CREAT)
        fcntl.flock(lock_fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        before = _listing(work)
    start = time.perf_counter()
    try:
        try:
            code = main(args)
        except SystemExit as exc:  # argparse
            code = exc.code
    finally:
        if lock_fd is not None:
            os.close(lock_fd)
    elapsed = time.perf_counter() - start
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2, f"exit {code}; stderr: {err}"
    assert len(lines) == 1, f"expected one stderr line, got: {err}"
    assert needle in lines[0], f"'{needle}' not in: {lines[0]}"
    assert "Traceback" not in err
    assert _listing(work) == before, "output or temporary files left behind"
    assert _listing(files["tracks"].parent) == files_before
    assert elapsed < LIMIT_S, f"took {elapsed:.1f} s"


# ------------------------------------------------------------------------------ real processes
ABU = [sys.executable, "-m", "abu.cli.main"]


@pytest.mark.parametrize("argv,needle", [
    (["simulate", "--m", "-inf"], "--m"),
    (["simulate", "--omega0-hz", "-1e6"], "--omega0-hz"),
    (["measure", "--tracks", "{tracks_ms}", "--out", "{out}"], "tracks_ms.csv"),
    (["measure-summary", "{sim_summary}", "--out", "{out}"], "sim_summary.json"),
])
def test_bad_input_in_a_real_process(argv, needle, files, tmp_path):
    mapping = {k: str(v) for k, v in files.items()}
    mapping["out"] = str(tmp_path / "out")
    start = time.perf_counter()
    proc = subprocess.run(ABU + _fill(argv, mapping), capture_output=True, text=True,
                          timeout=60, cwd=Path(__file__).parent.parent)
    elapsed = time.perf_counter() - start
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2, proc.stderr
    assert len(lines) == 1 and needle in lines[0], proc.stderr
    assert not (tmp_path / "out").exists() and not list(tmp_path.iterdir())
    assert elapsed < LIMIT_S


def test_unexpected_error_is_one_line_exit_1_and_debug_shows_the_traceback(tmp_path,
                                                                             monkeypatch, capsys):
    import measurement.report.multi as multi

    def broken(*args, **kwargs):
        raise ZeroDivisionError("simulated bug")

    monkeypatch.setattr(multi, "combine_summaries", broken)
    good = tmp_path / "s.json"
    good.write_text(json.dumps({"mu_low": 0.02, "mu_high": 0.03}))
    out = tmp_path / "out"
    assert main(["measure-summary", str(good), "--out", str(out)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "measure-summary" in err[0] and "s.json" in err[0]
    assert "ZeroDivisionError" in err[0] and "--debug" in err[0]
    assert not out.exists() and sorted(p.name for p in tmp_path.iterdir()) == ["s.json"]
    assert main(["--debug", "measure-summary", str(good), "--out", str(out)]) == 1
    assert "Traceback" in capsys.readouterr().err


def test_negative_values_in_both_spellings_reach_the_option(capsys):
    from abu.cli.main import build_parser

    parser = build_parser()
    for argv in (["simulate", "--omega0-hz", "-1e6"], ["simulate", "--omega0-hz=-1e6"]):
        assert parser.parse_args(argv).omega0_hz == -1e6
    assert parser.parse_args(["simulate", "--m", "-inf"]).m == -np.inf
    assert parser.parse_args(["simulate", "--beta0", "-.5"]).beta0 == -0.5
    assert parser.parse_args(["table41", "--mu", "-1", "-2e-3"]).mu == [-1.0, -2e-3]


def test_overwrite_never_replaces_the_current_folder_or_above(tmp_path, monkeypatch, capsys):
    work = tmp_path / "a" / "b"
    work.mkdir(parents=True)
    (work / "keep.txt").write_text("user's file")
    monkeypatch.chdir(work)
    for out in (".", str(work), str(tmp_path / "a")):
        assert main(["simulate", "--out", out, "--overwrite", "--te", "-1"]) == 2  # bad --te
        assert main(["simulate", "--out", out, "--overwrite"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 2 and "current folder" in err[-1]
    assert (work / "keep.txt").read_text() == "user's file"
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["a", "b", "keep.txt"]
