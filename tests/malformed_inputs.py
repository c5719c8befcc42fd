"""A corpus of malformed or physically impossible inputs, made by mutating valid ones (issue 19).

Not a test module: :func:`build_corpus` writes the valid originals and their mutations into a
folder and returns the cases ``(reader, argv, needle)``: running ``abu ARGV`` must exit 2 with
one stderr line containing ``needle`` (the file or the option) and write nothing. ``{out}`` in
argv is a fresh output folder.

Mutations: wrong JSON types (string, boolean, list, object, null), NaN / infinite / huge /
negative values, duplicated keys and columns, duplicated, swapped and reordered rows, truncated
and concatenated files, swapped and duplicated markers, markers off their circles, markers
the geometry excludes, wrong kinds of file for every reader, options a mode ignores, malformed
scheduler addresses.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from synthetic_tracks import measured_pixels, simulate

HEADER = "time,x_center,y_center,x_cd,y_cd,x_ball,y_ball"
COLUMNS = HEADER.split(",")
BAD_CELLS = ("abc", "nan", "inf", "-inf", "1e999", "", "true", "0x10", "1_0")
BAD_JSON_VALUES = ("str", True, False, [0.02], {"v": 0.02}, None, -1.0, 1e300, "NaN", "nan_lit")


def _tracks_rows(n: int = 400) -> list[str]:
    rec = simulate(0.02, "steps", n=n)
    x, y = measured_pixels(rec, sigma_px=0.02, harmonic_px=0.4, seed=11)
    return [",".join(f"{v:.6f}" for v in (t, *np.ravel(np.c_[xi, yi])))
            for t, xi, yi in zip(rec.time, x, y)]


def _xy(rows: list[str]) -> np.ndarray:
    return np.array([[float(c) for c in r.split(",")] for r in rows])


def _rows_of(a: np.ndarray) -> list[str]:
    return [",".join(f"{v:.9g}" for v in r) for r in a]


def _json_text(obj: dict, key: str | None = None, value=None) -> str:
    """``obj`` as JSON with ``key`` set to ``value`` (``"nan_lit"``: the bare NaN literal)."""
    d = dict(obj)
    if key is not None:
        d[key] = "__NAN__" if value == "nan_lit" else value
    return json.dumps(d).replace('"__NAN__"', "NaN")


class Corpus:
    def __init__(self, folder: Path):
        self.folder = folder
        self.cases: list[tuple[str, list[str], str]] = []
        self.n = 0

    def file(self, name_hint: str, content: str | bytes, suffix: str) -> Path:
        self.n += 1
        p = self.folder / f"{name_hint}_{self.n:04d}{suffix}"
        if isinstance(content, bytes):
            p.write_bytes(content)
        else:
            p.write_text(content)
        return p

    def add(self, reader: str, argv: list[str], needle: str) -> None:
        self.cases.append((reader, argv, needle))


def _tracks_cases(c: Corpus, good: Path, rows: list[str]) -> None:
    def measure(p: Path) -> None:
        c.add("tracks CSV", ["measure", "--tracks", str(p), "--out", "{out}", "--no-plots"],
              p.name)

    def write(lines: list[str], header: str = HEADER) -> None:
        measure(c.file("tracks", "\n".join([header] + lines) + "\n", ".csv"))

    # a bad cell in every column, at the start, the middle and the end
    for j, col in enumerate(COLUMNS):
        for bad in BAD_CELLS:
            for r in (0, len(rows) // 2):
                cells = rows[r].split(",")
                cells[j] = bad
                write(rows[:r] + [",".join(cells)] + rows[r + 1:])
    a = _xy(rows)
    # huge but finite values reaching the geometry
    for j in range(1, 7):
        for v in (1e300, -1e300, 1e7, 1e154):
            b = a.copy()
            b[len(b) // 3, j] = v
            write(_rows_of(b))
    # duplicated, swapped, reversed rows; a file concatenated with itself; truncated
    write(rows[:100] + [rows[99]] + rows[100:])
    write(rows[:100] + [rows[101], rows[100]] + rows[102:])
    write(rows[::-1])
    write(rows + rows)
    write(rows[:10])
    write([])
    text = good.read_text()
    measure(c.file("tracks", text[: len(text) // 2 + 7], ".csv"))      # cut inside a row
    measure(c.file("tracks", text[: len(text) // 2 + 7] + "\n" + text[len(text) // 2:], ".csv"))
    # duplicated and ambiguous columns
    write([r + "," + r.split(",")[1] for r in rows], HEADER + ",x_center")
    write([r + "," + r.split(",")[0] for r in rows], HEADER + ",time_s")
    write(rows, HEADER.replace("x_ball", "x_bal"))
    # markers the geometry excludes (time column kept)
    for name, change in {
        "ball=centre": lambda b: b.__setitem__((slice(None), slice(5, 7)), b[:, 1:3]),
        "cd=centre": lambda b: b.__setitem__((slice(None), slice(3, 5)), b[:, 1:3]),
        "ball=cd": lambda b: b.__setitem__((slice(None), slice(5, 7)), b[:, 3:5]),
        "all=centre": lambda b: b.__setitem__((slice(None), slice(3, 7)),
                                              np.c_[b[:, 1:3], b[:, 1:3]]),
        "ball drifts off its circle": lambda b: b.__setitem__(
            (slice(None), 5), b[:, 5] + np.linspace(0, 80, len(b))),
        "cd jumps off its circle": lambda b: b.__setitem__(
            (slice(150, 160), slice(3, 5)), b[150:160, 1:3] + 1.5 * (b[150:160, 3:5]
                                                                      - b[150:160, 1:3])),
        "centre moves": lambda b: b.__setitem__((slice(None), 1), b[:, 1] + np.linspace(0, 90,
                                                                                        len(b))),
        "tiny scale": lambda b: b.__setitem__((slice(None), slice(1, 7)), b[:, 1:7] * 1e-150),
        "huge scale": lambda b: b.__setitem__((slice(None), slice(1, 7)), b[:, 1:7] * 1e150),
        "ball teleports": lambda b: b.__setitem__((200, slice(5, 7)), [0.0, 0.0]),
    }.items():
        b = a.copy()
        change(b)
        write(_rows_of(b))
    # swapped markers: CD and ball, centre and ball, centre and CD (a record of two turns and
    # more: the role check needs them)
    long = _xy(_tracks_rows(1500))
    for i, j in ((3, 5), (1, 5), (1, 3)):
        b = long.copy()
        b[:, [i, i + 1, j, j + 1]] = b[:, [j, j + 1, i, i + 1]]
        write(_rows_of(b))
    # lost column: bad masks, a marker lost for a block of frames or at the ends
    for bad in ("8", "-1", "x", "inf", "1.5", "nan"):
        write([r + ("," + bad if k == 50 else ",0") for k, r in enumerate(rows)], HEADER + ",lost")
    for lo, hi, mask in ((100, 120, 4), (0, 3, 2), (len(rows) - 2, len(rows), 1), (10, 30, 7)):
        write([r + ("," + str(mask) if lo <= k < hi else ",0") for k, r in enumerate(rows)],
              HEADER + ",lost")
    # wrong kinds of file
    measure(c.file("tracks", json.dumps({"mu_low": 0.02, "mu_high": 0.03}), ".csv"))
    measure(c.file("tracks", bytes(range(256)) * 4, ".csv"))
    measure(c.file("tracks", "time_s,omega_rad_s\n" + "\n".join(f"{k},{k}" for k in range(50)),
                   ".csv"))


SUMMARY = {"kind": "abu-measure-summary", "format_version": 1, "mu_low": 0.02, "mu_high": 0.03}


def _summary_cases(c: Corpus, good: Path) -> None:
    def summary(text: str | bytes, suffix: str = ".json") -> None:
        p = c.file("summary", text, suffix)
        c.add("summary JSON", ["measure-summary", str(good), str(p), "--out", "{out}"], p.name)

    for key in ("mu_low", "mu_high"):
        for v in BAD_JSON_VALUES:
            if v is None:
                continue  # a missing bound (null) is valid
            summary(_json_text(SUMMARY, key, v))
        summary(_json_text(SUMMARY, key, "0.025"))
        summary(_json_text({k: v for k, v in SUMMARY.items() if k != key}))
    for v in (True, "1", 2, None, 1.5):
        summary(_json_text(SUMMARY, "format_version", v))
    for v in (5, "abu-simulate-summary", "abu-drive", True):
        summary(_json_text(SUMMARY, "kind", v))
    summary(json.dumps(SUMMARY)[:-1] + ', "mu_low": 0.5}')        # a key given twice
    summary(json.dumps(SUMMARY)[: len(json.dumps(SUMMARY)) // 2])  # truncated
    summary(json.dumps([SUMMARY]))
    summary(json.dumps(SUMMARY) + json.dumps(SUMMARY))             # two objects
    summary(_json_text(SUMMARY, "mu_low", 0.05))                    # inverted
    summary("")
    summary(b"\xff\xfe\x00garbage")
    summary("[" * 5000 + "]" * 5000)
    summary(HEADER + "\n1,2,3,4,5,6,7\n")                           # a tracks CSV named .json
    summary(json.dumps({"kind": "abu-drive", "format_version": 1, "model": "second-order",
                        "zeta": 0.5, "omega_n_rad_s": 2.2}))
    # intervals CSV
    for text in ("mu_low,mu_high\n", "mu_low,mu_high,mu_low\n0.01,0.02,0.03\n",
                 "mu_low,mu_high\nabc,0.02\n", "mu_low,mu_high\nnan,0.02\n",
                 "mu_low,mu_high\n-1,0.02\n", "mu_low,mu_high\n0.03,0.02\n",
                 "mu_low,mu_high\ntrue,0.02\n", "mu_low,mu_high\n0.01,0.02,7\n",
                 "mu_low,mu_high\n0.01\n", "mu_low,mu_high\n,\n", "mu_low,mu_high\n1e999,\n",
                 "mu_low,mu_high\n0.01,1e300\n", "a,b\n1,2\n", "", HEADER + "\n1,2,3,4,5,6,7\n",
                 "mu_low;mu_high\n0.01;0.02\n"):
        summary(text, ".csv")


DRIVE = {"kind": "abu-drive", "format_version": 1, "model": "pi-lag",
         "theta_ref_mode": "integral", "zeta": 0.7, "omega_n_rad_s": 12.0, "tau_motor_s": 0.02,
         "setpoint_weight": 1.0}


def _drive_cases(c: Corpus) -> None:
    def drive(text: str | bytes) -> None:
        p = c.file("drive", text, ".json")
        c.add("drive.json", ["simulate", "--drive", str(p), "--out", "{out}"], p.name)

    for key in ("zeta", "omega_n_rad_s", "tau_motor_s"):
        for v in BAD_JSON_VALUES:
            if key == "tau_motor_s" and v is None:
                continue
            drive(_json_text(DRIVE, key, v))
    for key, values in {"kind": ("abu-camera", 1, None), "format_version": (True, "1", 2),
                        "model": ("linear", 1, None), "theta_ref_mode": ("thesis", 0),
                        "setpoint_weight": (2.0, "1")}.items():
        for v in values:
            drive(_json_text(DRIVE, key, v))
    for v in ([1.0], [2.0, 1.0], [0.5, "x"], [0.5, True], "0.5,0.9", [0.5, math.inf]):
        drive(json.dumps({**DRIVE, "zeta_ci95": v}, allow_nan=True))
    # impossible physics: a loop beyond the Routh-Hurwitz limit (2 zeta / omega_n = 0.117 s),
    # intervals outside their field's range
    drive(json.dumps({**DRIVE, "tau_motor_s": 0.2}))
    drive(json.dumps({**DRIVE, "tau_motor_s_ci95": [-0.01, 0.03]}))
    drive(json.dumps({**DRIVE, "omega_n_rad_s_ci95": [10.0, 2.0e4]}))
    drive(json.dumps(DRIVE)[:-1] + ', "zeta": 5.0}')
    drive(json.dumps(DRIVE)[:40])
    drive(json.dumps([DRIVE]))
    drive(HEADER + "\n")
    drive(json.dumps(SUMMARY))


def _camera_cases(c: Corpus, good_tracks: Path, camera: dict) -> None:
    def cam(text: str | bytes) -> None:
        p = c.file("camera", text, ".json")
        c.add("camera.json", ["measure", "--tracks", str(good_tracks), "--camera", str(p),
                              "--out", "{out}", "--no-plots"], p.name)

    for key in ("camera_matrix", "dist_coeffs", "image_size_px", "reprojection_rms_px",
                "n_views"):
        for v in ("str", True, None, [1, 2], 1e300, "nan_lit", [[True, 0, 0], [0, 1, 0],
                                                                  [0, 0, 1]]):
            cam(_json_text(camera, key, v))
    for v in (True, "1", 2):
        cam(_json_text(camera, "format_version", v))
    cam(json.dumps(camera)[:-1] + ', "n_views": 3}')
    cam(json.dumps(camera)[:60])
    cam(json.dumps(DRIVE))
    cam(HEADER + "\n")


def _record_cases(c: Corpus, good_record: Path) -> None:
    staircase = ["--omega0-hz", "-9", "--omega-end-hz", "-19", "--te", "0.5"]

    def record(text: str) -> None:
        p = c.file("record", text, ".csv")
        c.add("identify record CSV", ["identify", "--record", str(p)] + staircase, p.name)

    def setpoints(text: str) -> None:
        p = c.file("setpoints", text, ".csv")
        c.add("identify setpoints CSV", ["identify", "--record", str(good_record),
                                         "--setpoints", str(p)], p.name)

    lines = good_record.read_text().splitlines()
    head, body = lines[0], lines[1:]
    for col in range(2):
        for bad in BAD_CELLS:
            cells = body[20].split(",")
            cells[col] = bad
            record("\n".join([head] + body[:20] + [",".join(cells)] + body[21:]) + "\n")
    record("\n".join([head] + body[:30] + [body[29]] + body[30:]) + "\n")
    record("\n".join([head] + body[::-1]) + "\n")
    record("\n".join([head + ",time_s"] + [r + ",0" for r in body]) + "\n")
    record("\n".join([head + ",omega"] + [r + ",0" for r in body]) + "\n")
    record("\n".join(["time_s,x"] + [f"{k},{k}" for k in range(40)]) + "\n")
    record(head + "\n" + "\n".join(body[:3]) + "\n")
    record("")
    record(json.dumps(DRIVE))
    for text in ("time_s,omega_ref_rad_s\n0,nan\n0.1,-60\n", "time_s,omega_ref_rad_s\n0,-56\n",
                 "time_s,omega_ref_rad_s\n0,-56\n0,-60\n", "time_s,omega_ref_rad_s\n0,abc\n1,2\n",
                 "time_s\n0\n1\n", "time_s,omega_ref_rad_s,omega_ref_rad_s\n0,1,2\n1,2,3\n",
                 "time_s,omega_ref_rad_s\n0.2,-56\n0.1,-60\n", ""):
        setpoints(text)


def _recording_cases(c: Corpus, stack: np.ndarray) -> None:
    import cv2

    def track(p: Path) -> None:
        c.add("recording", ["track", str(p), "--out", "{out}"], p.name)

    def npy(a: np.ndarray) -> Path:
        p = c.file("rec", b"", ".npy")
        np.save(p, a)
        return p

    for a in (stack[:, :, 0].copy(), stack.astype(np.float32), stack.astype(np.int16),
              stack.astype(np.float64) * np.nan, np.zeros((0, 16, 16), np.uint8),
              np.zeros((4, 0, 8), np.uint8), stack.astype(bool)):
        track(npy(a))
    full = npy(stack).read_bytes()
    for cut in (10, 80, len(full) // 2, len(full) - 1):
        track(c.file("rec", full[:cut], ".npy"))
    for text, suffix in ((HEADER + "\n", ".tif"), (json.dumps(SUMMARY), ".npy"),
                         (HEADER + "\n1,2\n", ".avi"), ("not an image", ".png")):
        track(c.file("rec", text, suffix))
    p = npy(stack[:2])
    c.add("recording", ["measure", str(p), "--out", "{out}"], p.name)
    # frame folders whose names do not define one frame order
    for names in (("img1.png", "img01.png", "img2.png"), ("a1.png", "a2.png", "b1.png"),
                  ("f1.png", "f2.png", "notes.png"), ("f1.png", "f3.png"),
                  ("f1.png", "f2.bmp")):
        c.n += 1
        d = c.folder / f"frames_{c.n:04d}"
        d.mkdir()
        for k, name in enumerate(names):
            cv2.imwrite(str(d / name), stack[k % len(stack)])
        track(d)


def _option_cases(c: Corpus, good_tracks: Path) -> None:
    from abu.cli.not_applicable import RENDER_REPORT_ONLY

    values = {"--drive": str(c.folder / "d.json"), "--fmu-dir": str(c.folder)}
    for opt in RENDER_REPORT_ONLY:
        c.add("options", ["render", "--scenario", "random", "--seed", "7", opt,
                          values.get(opt, "0.02"), "--out", "{out}"], opt)
    for opt in ("--size", "--lighting"):
        c.add("options", ["render", opt, "300" if opt == "--size" else "ring", "--out", "{out}"],
              opt)
    for opt, v in (("--omega-end-hz", "-20"), ("--t0", "0.1"), ("--te", "2"), ("--step-hz", "2"),
                   ("--rounding", "trail"), ("--theta-ref", "thesis"), ("--zeta", "0.7"),
                   ("--omega-n", "3")):
        c.add("options", ["simulate", "--motion", "ramp", opt, v, "--out", "{out}"], opt)
    c.add("options", ["simulate", "--jerk", "100", "--out", "{out}"], "--jerk")
    c.add("options", ["simulate", "--tol", "1e-6", "--comm-step", "1e-3", "--out", "{out}"],
          "--comm-step")
    c.add("options", ["simulate", "--overwrite"], "--overwrite")
    for opt, v in (("--seeds", "1,2;30,40;60,70"), ("--method", "moments"), ("--window", "20"),
                   ("--ball-method", "pair"), ("--dark-markers", None), ("--progress", None)):
        c.add("options", ["measure", "--tracks", str(good_tracks), opt] + ([v] if v else [])
              + ["--out", "{out}"], opt)
    # --ball-reflections says how the tracked ball looked: only 1 or 2
    c.add("options", ["measure", "--tracks", str(good_tracks), "--ball-reflections", "3",
                      "--out", "{out}"], "--ball-reflections")
    c.add("options", ["measure", "--tracks", str(good_tracks), "--poly-degree", "5", "--out",
                      "{out}"], "--poly-degree")
    c.add("options", ["measure", "--tracks", str(good_tracks), "--no-harmonic",
                      "--harmonic-phase", "abu", "--out", "{out}"], "--harmonic-phase")
    c.add("options", ["measure", "--tracks", str(good_tracks), "--no-harmonic",
                      "--lighting-models", "two", "--out", "{out}"], "--lighting-models")
    c.add("options", ["measure", "--tracks", str(good_tracks), "--lighting-models", "three",
                      "--out", "{out}"], "--lighting-models")
    c.add("options", ["measure", "--tracks", str(good_tracks), "--seed", "3", "--out", "{out}"],
          "--seed")
    c.add("options", ["track", str(good_tracks), "--ball-method", "pair", "--out", "{out}"],
          "--ball-method")
    c.add("options", ["identify", "--record", str(good_tracks), "--pulses-per-rev", "4"],
          "--pulses-per-rev")
    c.add("options", ["design", "--mu-range", "0.01", "0.03", "--no-check", "--fmu-dir",
                      str(c.folder)], "--fmu-dir")
    for seeds in ("10,10;10,10;30,30", "5,5;40,40;40,41", "1,1;1,1;1,1"):
        c.add("options", ["track", str(c.folder), "--seeds", seeds, "--out", "{out}"], "--seeds")
    for address in ("tcp://", "http://host:8786", "tcp://host:port", "tcp://host:0",
                    "tcp://host:99999", "two words", ":8786", "[::1", "tcp://-host:1"):
        c.add("options", ["sweep", "--mu", "0.01", "--omega0-hz", "-17", "--scheduler", address,
                          "--out", "{out}.csv"], "--scheduler")


def build_corpus(folder: Path) -> list[tuple[str, list[str], str]]:
    """Write the valid originals and the mutated files into ``folder``; return the cases."""
    c = Corpus(folder)
    rows = _tracks_rows()
    good = folder / "good_tracks.csv"
    good.write_text("\n".join([HEADER] + rows) + "\n")
    good_summary = folder / "good_summary.json"
    good_summary.write_text(json.dumps(SUMMARY))
    t = np.arange(300) / 500.0
    omega = -2 * math.pi * (9 + 10 * (1 - np.exp(-t / 0.1)))
    good_record = folder / "good_record.csv"
    good_record.write_text("time_s,omega_rad_s\n" + "\n".join(
        f"{a:.6f},{b:.6f}" for a, b in zip(t, omega)) + "\n")
    camera = {"kind": "abu-camera", "format_version": 1,
              "camera_matrix": [[500.0, 0, 128.0], [0, 500.0, 128.0], [0, 0, 1]],
              "dist_coeffs": [0.0, 0.0, 0.0, 0.0, 0.0], "image_size_px": [256, 256],
              "reprojection_rms_px": 0.1, "n_views": 10, "n_corners": 540}
    stack = np.random.default_rng(0).integers(0, 255, size=(6, 24, 20), dtype=np.uint8)
    _tracks_cases(c, good, rows)
    _summary_cases(c, good_summary)
    _drive_cases(c)
    _camera_cases(c, good, camera)
    _record_cases(c, good_record)
    _recording_cases(c, stack)
    _option_cases(c, good)
    return c.cases
