"""A corpus of malformed or impossible inputs, mutated from valid ones (issue 19), and
hypothesis fuzzing of every reader.

Each corpus case (tests/malformed_inputs.py) runs ``abu`` in-process through
``abu.cli.main.main`` and asserts: exit status 2, exactly one line on stderr naming the file or
the option, no "internal error", nothing written (the output folder absent, the corpus folder
unchanged). A sample runs through the real ``abu`` executable. The corpus size by reader is
printed (``pytest -s``).

The fuzzing feeds each reader (tracks CSV, summaries and intervals CSV, drive.json,
camera.json, identify's record and setpoints CSV) random mutations of a valid file: it raises
nothing but the toolkit's error type, and what it accepts is finite and in range.
"""
from __future__ import annotations

import collections
import json
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from abu.cli.main import main
from abu_model.errors import AbuError

from malformed_inputs import DRIVE, HEADER, SUMMARY, build_corpus

SETTINGS = dict(deadline=None, derandomize=True, max_examples=60,
                suppress_health_check=[HealthCheck.function_scoped_fixture,
                                       HealthCheck.too_slow])


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    folder = tmp_path_factory.mktemp("malformed")
    return folder, build_corpus(folder)


def _listing(folder: Path) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob("*")}


def _run(argv: list[str], out: Path, capsys) -> tuple[int, str]:
    args = [a.replace("{out}", str(out)) for a in argv]
    try:
        code = main(args)
    except SystemExit as exc:  # argparse
        code = exc.code
    return code, capsys.readouterr().err


def test_the_corpus_is_large_and_every_case_is_refused_in_one_line(corpus, tmp_path, capsys):
    folder, cases = corpus
    sizes = collections.Counter(reader for reader, _, _ in cases)
    with capsys.disabled():
        print(f"\nmalformed-input corpus: {len(cases)} cases")
        for reader, n in sorted(sizes.items()):
            print(f"  {reader:<24} {n}")
    assert len(cases) >= 400
    assert len({tuple(a) for _, a, _ in cases}) == len(cases)
    before = _listing(folder)
    failures = []
    for k, (reader, argv, needle) in enumerate(cases):
        out = tmp_path / f"out{k}"
        code, err = _run(argv, out, capsys)
        lines = [line for line in err.splitlines() if line.strip()]
        problem = None
        if code != 2:
            problem = f"exit {code}"
        elif len(lines) != 1:
            problem = f"{len(lines)} stderr lines"
        elif needle not in lines[0]:
            problem = f"'{needle}' not named"
        elif "internal error" in lines[0] or "Traceback" in err:
            problem = "internal error"
        elif out.exists() or Path(str(out) + ".csv").exists():
            problem = "output written"
        if problem:
            failures.append(f"[{reader}] {' '.join(argv)[:160]}: {problem}: {err.strip()[:300]}")
    assert not failures, f"{len(failures)} of {len(cases)} cases failed:\n" + "\n".join(
        failures[:60])
    assert _listing(folder) == before, "the command wrote into the corpus folder"
    assert list(tmp_path.iterdir()) == []


def test_a_sample_through_the_real_executable(corpus, tmp_path):
    folder, cases = corpus
    abu = shutil.which("abu", path=os.path.dirname(sys.executable))
    assert abu is not None, "the abu entry point is not installed next to the interpreter"
    by_reader = {}
    for reader, argv, needle in cases:
        by_reader.setdefault(reader, (argv, needle))
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).parent.parent)}
    for reader, (argv, needle) in by_reader.items():
        out = tmp_path / "out"
        proc = subprocess.run([abu] + [a.replace("{out}", str(out)) for a in argv],
                              capture_output=True, text=True, timeout=120, env=env)
        lines = proc.stderr.strip().splitlines()
        assert proc.returncode == 2, (reader, proc.stderr)
        assert len(lines) == 1 and needle in lines[0], (reader, proc.stderr)
        assert "internal error" not in proc.stderr
        assert not out.exists()


# ------------------------------------------------------------------------------ fuzzing
def _mutate(text: str, edits) -> str:
    for position, kind, payload in edits:
        i = int(position * len(text)) if text else 0
        if kind == 0:
            text = text[:i] + text[i + 1:]
        elif kind == 1:
            text = text[:i] + payload + text[i:]
        elif kind == 2:
            text = text[:i]
        else:
            text = text[:i] + text[i:] + text[i:]  # a duplicated tail
    return text


edits = st.lists(st.tuples(st.floats(0, 1, exclude_max=True), st.integers(0, 3),
                           st.sampled_from([",", "\n", "nan", "1e999", "-", "e", "9", '"', "true",
                                            "{", "]", "0", ".", "x", "1e300", "null"])),
                 min_size=1, max_size=4)


@pytest.fixture(scope="module")
def originals(tmp_path_factory):
    from malformed_inputs import _tracks_rows
    rows = _tracks_rows(60)
    t = np.arange(60) / 500.0
    return {
        "tracks": "\n".join([HEADER] + rows) + "\n",
        "summary": json.dumps(SUMMARY),
        "intervals": "mu_low,mu_high,name\n0.01,0.02,a\n0.015,0.03,b\n",
        "drive": json.dumps(DRIVE),
        "camera": json.dumps({"kind": "abu-camera", "format_version": 1,
                              "camera_matrix": [[500.0, 0, 128.0], [0, 500.0, 128.0], [0, 0, 1]],
                              "dist_coeffs": [0.0, 0.0, 0.0, 0.0, 0.0],
                              "image_size_px": [256, 256], "reprojection_rms_px": 0.1,
                              "n_views": 10, "n_corners": 540}),
        "record": "time_s,omega_rad_s\n" + "\n".join(f"{a:.5f},{-60 + a:.5f}" for a in t) + "\n",
        "setpoints": "time_s,omega_ref_rad_s\n0,-56.5\n0.1,-62.8\n0.2,-69.1\n",
    }


def _read(kind: str, path: Path):
    if kind == "tracks":
        from measurement.imaging.tracks_io import read_tracks_csv
        t = read_tracks_csv(path)
        assert np.isfinite(t.x).all() and np.isfinite(t.y).all() and (np.diff(t.time) > 0).all()
        assert (np.abs(t.x) <= 1e6).all() and (np.abs(t.y) <= 1e6).all()
    elif kind in ("summary", "intervals"):
        from measurement.report.multi import read_intervals
        for row in read_intervals([path]):
            assert 0 <= row["mu_low"] <= row["mu_high"] and math.isfinite(row["mu_low"])
    elif kind == "drive":
        from controller.drive import load_drive
        d = load_drive(path)
        assert all(math.isfinite(v) and v >= 0 for v in (d.zeta, d.omega_n, d.tau_motor))
    elif kind == "camera":
        from measurement.imaging.camera import read_camera
        cam = read_camera(path)
        assert np.isfinite(cam.camera_matrix).all() and np.isfinite(cam.dist_coeffs).all()
    elif kind == "record":
        from harness.planning.record_io import read_record
        r = read_record(path)
        assert np.isfinite(r.y).all() and (np.diff(r.t) > 0).all()
    else:
        from harness.planning.record_io import read_setpoints
        s = read_setpoints(path)
        assert all(math.isfinite(v) for v in s.levels)


@pytest.mark.parametrize("kind", ["tracks", "summary", "intervals", "drive", "camera", "record",
                                  "setpoints"])
def test_every_reader_on_mutated_files(kind, originals, tmp_path):
    suffix = {"summary": ".json", "drive": ".json", "camera": ".json"}.get(kind, ".csv")
    path = tmp_path / f"input{suffix}"
    _read_ok = {"n": 0, "refused": 0}

    @settings(**SETTINGS)
    @given(edits)
    def run(e):
        path.write_text(_mutate(originals[kind], e))
        try:
            _read(kind, path)
            _read_ok["n"] += 1
        except AbuError as exc:
            _read_ok["refused"] += 1
            assert str(path) in str(exc) or path.name in str(exc), str(exc)

    path.write_text(originals[kind])
    _read(kind, path)  # the original is valid
    run()
    assert _read_ok["refused"] > 0
