"""Every command's output is unchanged by the restructuring into ``abu/``, ``twin/`` and the
measurement stages (issue 17): the code before it (commit :data:`BEFORE`, taken from this
repository's history with ``git archive``) and the code now run the same commands on fixed
seeds, and every CSV column and JSON field they write is compared (paths and timings aside).

The only differences allowed are the ones the issue asked for, applied to the old output
before comparing (:func:`_upgrade`): one spelling per column across our CSV files (truth.csv
takes tracks.csv's ``x_center_px``), ``format_version`` beside ``kind`` in every JSON
(old ``version``), and ``abu table41 --json`` as an object with ``kind`` and ``units``; and
issue 18's honesty changes: the running max's ``status`` says what its bounds are instead of
"ok", and the top-level ``t_slip_low`` / ``t_slip_high`` are the model's onset bracket (the
running max's stay under ``running_max``, compared there); ``abu design`` / ``abu next`` rank
their candidates by the predicted measured width (:data:`DESIGN_CHOSEN`). Issue 20's compiled
tracker moved the tracked positions by <= 3e-7 px: the numbers computed from them are compared
to a stated tolerance (:data:`TRACKED_OUTPUTS`); this checkout runs
with ``InferenceOptions.drive_noise`` off and no ``leftover_orders`` (see :func:`_run`). Issue 20's edge step, on by
default for the centre and CD markers, moves their positions by ~0.02 px: every command runs
with it off here, and ``abu track``'s default output is compared apart, its positions and
angles to the tolerances :data:`EDGE_STEP_PX` / :data:`EDGE_STEP_RAD`.
"""
from __future__ import annotations

import csv
import json
import math
import os
import subprocess
import sys
import tarfile
from pathlib import Path

import pytest

from measurement.inference.running_max import BOUNDS_STATUS

ROOT = Path(__file__).resolve().parents[1]
#: The last commit before the restructuring.
BEFORE = "e8e7c928c8c3dcc9bddc6d3abcd7c80941a04ec9"
#: Fields that hold a path, a wall time or a build's identity (they differ between any runs).
VOLATILE = {"source", "file", "fmu_dir", "wall_time_s", "elapsed_s", "guid", "generated",
            "generationDateAndTime"}
#: Issue 20: the isocontour refinement went from float32 NumPy to float64 (NumPy and the C
#: kernel, which agree to 1e-12 px): tracked positions moved by <= 3e-7 px (measured: 2.3e-7 px
#: on the bench recording), so every number computed from them moved in its last digits. In
#: the outputs of the commands that track frames (stdout names, or output folders) numbers are
#: compared to these tolerances: positions [px] (CSV columns ``*_px``) 1e-6 px; every other
#: number relative 1e-4 (largest change seen 2.4e-5: the tracking-noise estimates, which are
#: differences of positions, and omega_dot, their second derivative; the mu bounds 2e-7).
TRACKED_OUTPUTS = ("stdout of measure-tracks", "stdout of measure-summary", "stdout of next",
                   "stdout of measure-random", "demo/measurement/", "track/", "mt/", "ms/",
                   "mr/")
TRACKED_JSON_REL = 1e-4
TRACKED_PX = 1e-6
#: Issue 20: the tracker's edge step (measurement/imaging/edge_step.py) is on by default for
#: the centre and CD markers of one-reflection recordings
#: (measurement.imaging.edge_step_roles.edge_step_default). It moves their tracked positions
#: by one least-squares step (measured on the demo's twin recording, the step on all three
#: markers: <= 0.020 px, RMS 0.005 px; theta <= 2.7e-4 rad, beta <= 7.3e-4 rad), and every interval
#: computed from them moves in a way no mapping predicts. So every command runs here with the
#: edge step off (the old default, see :func:`_run`), and ``abu track``'s default output is
#: compared apart (:func:`_compare_edge_step_tracks`): positions (``*_px``) within
#: EDGE_STEP_PX, theta and beta within EDGE_STEP_RAD (0.05 px over the ~36 px from the ball
#: to the CD marker, twice), the lost flags equal, ``tracking.json`` equal but ``edge_step``.
EDGE_STEP_PX = 0.05
EDGE_STEP_RAD = 3e-3
TRUTH_RENAMED = {"centre_x_px": "x_center_px", "centre_y_px": "y_center_px",
                 "cd_x_px": "x_cd_px", "cd_y_px": "y_cd_px", "ball_x_px": "x_ball_px",
                 "ball_y_px": "y_ball_px", "ball_apparent_x_px": "x_ball_apparent_px",
                 "ball_apparent_y_px": "y_ball_apparent_px", "axis_x_px": "x_axis_px",
                 "axis_y_px": "y_axis_px"}


@pytest.fixture(scope="module")
def before_tree(tmp_path_factory) -> Path:
    """The source tree of :data:`BEFORE` (from git; the test needs the repository's history)."""
    dest = tmp_path_factory.mktemp("before")
    archive = dest / "before.tar"
    proc = subprocess.run(["git", "-C", str(ROOT), "archive", "--format=tar", "-o",
                           str(archive), BEFORE], capture_output=True, text=True)
    assert proc.returncode == 0, ("the before/after comparison needs the commit "
                                  f"{BEFORE} in this clone's history: {proc.stderr}")
    with tarfile.open(archive) as tar:
        tar.extractall(dest, filter="data")
    return dest


def _run(tree: Path | None, cwd: Path, *args: str, edge_step_default: bool = False) -> str:
    """``abu ARGS`` of the tree ``tree`` (None: this checkout, with the tracker's edge step off
    unless ``edge_step_default``, see :data:`EDGE_STEP_PX`); its stdout."""
    env = dict(os.environ, MPLBACKEND="Agg", PYTHONHASHSEED="0")
    if tree is None:
        # Deliberate value change (issue 18): omega_dot's noise in the predicted slip
        # (InferenceOptions.drive_noise, tests/test_drive_noise.py) moves every model-based
        # interval and what is computed from one (measure, measure-summary, design, next).
        # Old values cannot be mapped to new ones, so this checkout runs with it off here;
        # every other output must still match the old commit field by field.
        # The same for the lighting orders 5-12 as random effects (leftover_orders,
        # tests/test_lighting_leftover.py): off here.
        code = ("import sys; from measurement.inference import types\n"
                "_init = types.InferenceOptions.__init__\n"
                "def _off(self, *a, drive_noise=False, leftover_orders=(), **k):\n"
                "    _init(self, *a, drive_noise=drive_noise, leftover_orders=leftover_orders, **k)\n"
                "types.InferenceOptions.__init__ = _off\n"
                + ("" if edge_step_default else
                   "from measurement.imaging import reflections\n"
                   "reflections.edge_step_default = lambda ball_reflections: (False,) * 3\n")
                + "from abu.cli.main import main; sys.exit(main(sys.argv[1:]))")
        env["PYTHONPATH"] = str(ROOT)
    else:
        code = "import sys; from harness.cli import main; sys.exit(main(sys.argv[1:]))"
        env["PYTHONPATH"] = str(tree)
    proc = subprocess.run([sys.executable, "-c", code, *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, (tree, args, proc.stderr[-3000:])
    return proc.stdout


def _commands(tmp: Path) -> list[tuple[str, list[str]]]:
    """(name, argv) run in order in one folder; later ones read earlier outputs."""
    return [
        ("demo", ["demo", "--out", "demo"]),
        ("track", ["track", "demo/twin", "--out", "track", "--quiet"]),
        ("measure-tracks", ["measure", "--tracks", "track/tracks.csv", "--out", "mt",
                            "--no-plots", "--json"]),
        ("measure-summary", ["measure-summary", "demo/measurement/summary.json",
                             "mt/summary.json", "--out", "ms", "--json"]),
        ("table41", ["table41", "--mu", "2.75e-3", "5.5e-3", "--no-check", "--json"]),
        ("design", ["design", "--mu-range", "0.02", "0.04", "--json"]),
        ("simulate", ["simulate", "--mu", "0.004", "--omega0-hz", "-20", "--omega-end-hz",
                      "-26", "--tau-motor", "0.01", "--json", "--out", "sim"]),
        ("export-ssp", ["export-ssp", "--out", "abu.ssp", "--mu", "0.004"]),
        ("render-random", ["render", "--scenario", "random", "--seed", "3", "--frames", "1200",
                           "--out", "rr", "--quiet"]),
        ("measure-random", ["measure", "rr", "--out", "mr", "--no-plots", "--json", "--quiet"]),
        ("next", ["next", "demo/measurement/summary.json", "mt/summary.json", "--json"]),
    ]


#: Fields of ``abu design`` / ``abu next`` that depend on the chosen staircase (issue 18 item
#: 3): the search now ranks its candidates by the width ``abu measure`` is predicted to report
#: (default objective ``predicted``, was the noise-free ``expected``), so another staircase may
#: win; the range, drive, camera limits and the report's widths are still compared.
DESIGN_CHOSEN = {"omega0_hz", "omega_end_hz", "t0_s", "te_s", "rounding", "simulate_args",
                 "render_args", "first_step_max_mu_req", "drive_ci_corners_hold", "objective",
                 "expected_relative_width", "worst_relative_width", "median_relative_width",
                 "table", "check", "predicted_worst_combined_width",
                 "predicted_median_combined_width", "predicted_combined"}


def _upgrade(obj):
    """The old output with the format changes the issue asked for."""
    if isinstance(obj, list) and obj and isinstance(obj[0], dict) and "omega0_hz" in obj[0]:
        return {"kind": "abu-table41", "rows": obj}  # table41 --json: now an object
    if isinstance(obj, dict):
        out = {k: _upgrade(v) for k, v in obj.items()}
        if "version" in out and "kind" in out:
            out["format_version"] = out.pop("version")
        if out.get("kind") in ("abu-design", "abu-next"):
            for key in DESIGN_CHOSEN:
                out.pop(key, None)
        rm = out.get("running_max")
        if isinstance(rm, dict) and "t_slip_low" in out:   # a measure summary (issue 18)
            out.pop("t_slip_low")
            out.pop("t_slip_high", None)
            if rm.get("status") == "ok":
                rm["status"] = BOUNDS_STATUS
        return out
    if isinstance(obj, list):
        return [_upgrade(v) for v in obj]
    if isinstance(obj, str):  # module names quoted in descriptions
        return obj.replace("measurement.render", "twin.render").replace(
            "measurement.scenario", "twin.scenario")
    return obj


def _comparable(obj, path=""):
    """``obj`` without volatile fields; floats as they are (the same code computes them)."""
    if isinstance(obj, dict):
        return {k: _comparable(v, f"{path}.{k}") for k, v in obj.items() if k not in VOLATILE}
    if isinstance(obj, list):
        return [_comparable(v, path) for v in obj]
    if isinstance(obj, float) and math.isnan(obj):
        return "nan"
    return obj


def _tracked(where: str) -> bool:
    return where.startswith(TRACKED_OUTPUTS)


def _differences(old, new, where: str) -> list[str]:
    """Every field of ``old`` that ``new`` lacks or holds differently (new may add fields)."""
    if isinstance(old, dict) and isinstance(new, dict):
        out = []
        for k, v in old.items():
            if k not in new:
                out.append(f"{where}.{k}: gone")
            else:
                out += _differences(v, new[k], f"{where}.{k}")
        return out
    if isinstance(old, list) and isinstance(new, list) and len(old) == len(new):
        return [d for i, (a, b) in enumerate(zip(old, new))
                for d in _differences(a, b, f"{where}[{i}]")]
    if (isinstance(old, float) and isinstance(new, float) and _tracked(where)
            and math.isclose(old, new, rel_tol=TRACKED_JSON_REL, abs_tol=1e-12)):
        return []  # issue 20: computed from positions moved by <= 3e-7 px
    return [] if old == new else [f"{where}: {old!r} -> {new!r}"[:300]]


def _csv_cells_close(header: list[str], old: list[list[str]], new: list[list[str]]) -> bool:
    """Same rows; numeric cells within the issue-20 tolerances (:data:`TRACKED_OUTPUTS`):
    positions (columns ``*_px``) within :data:`TRACKED_PX` px, other numbers within
    :data:`TRACKED_JSON_REL` of their column's largest magnitude (a column's values near zero,
    e.g. a bias changing sign, move as much as its large ones); text equal."""
    if len(old) != len(new) or any(len(a) != len(b) for a, b in zip(old, new)):
        return False

    def number(cell: str) -> float | None:
        try:
            return float(cell)
        except ValueError:
            return None

    scale = [max((abs(v) for row in old if (v := number(row[j])) is not None
                  and math.isfinite(v)), default=0.0) for j in range(len(header))]
    for row_old, row_new in zip(old, new):
        for j, (a, b) in enumerate(zip(row_old, row_new)):
            if a == b:
                continue
            fa, fb = number(a), number(b)
            if fa is None or fb is None:
                return False
            tol = TRACKED_PX if header[j].endswith("_px") else TRACKED_JSON_REL * scale[j]
            if not abs(fa - fb) <= tol:
                return False
    return True


def _json_equal(old, new, where: str) -> None:
    diffs = _differences(_comparable(_upgrade(old)), _comparable(new), where)
    assert not diffs, "\n".join(diffs)


def _read_csv(path: Path) -> tuple[list[str], list[list[str]]]:
    with path.open(newline="", encoding="utf-8") as fh:
        rows = list(csv.reader(fh))
    header = [TRUTH_RENAMED.get(h, h) for h in rows[0]] if path.name == "truth.csv" else rows[0]
    return header, rows[1:]


def _compare_files(old_dir: Path, new_dir: Path) -> list[str]:
    compared = []
    for old in sorted(old_dir.rglob("*")):
        rel = old.relative_to(old_dir)
        if old.suffix not in (".csv", ".json") or old.name.startswith("."):
            continue
        new = new_dir / rel
        assert new.exists(), f"{rel} is no longer written"
        if old.suffix == ".csv" and _tracked(rel.as_posix()):
            (h_new, rows_new), (h_old, rows_old) = _read_csv(new), _read_csv(old)
            assert h_new == h_old and _csv_cells_close(h_old, rows_old, rows_new), rel
        elif old.suffix == ".csv":
            assert _read_csv(new) == _read_csv(old), rel
        else:
            _json_equal(json.loads(old.read_text()), json.loads(new.read_text()), rel.as_posix())
        compared.append(str(rel))
    return compared


def _compare_edge_step_tracks(old_dir: Path, new_dir: Path) -> None:
    """``abu track``'s output with the edge step (the default) against the old one: the
    changed fields to :data:`EDGE_STEP_PX` / :data:`EDGE_STEP_RAD`, the rest equal."""
    (h_old, old), (h_new, new) = (_read_csv(d / "tracks.csv") for d in (old_dir, new_dir))
    assert h_new == h_old
    assert len(new) == len(old)
    moved = 0.0
    for row_old, row_new in zip(old, new):
        for name, a, b in zip(h_old, row_old, row_new):
            if name.endswith("_px") or name in ("theta_rad", "beta_rad"):
                tol = EDGE_STEP_PX if name.endswith("_px") else EDGE_STEP_RAD
                assert abs(float(a) - float(b)) <= tol, (name, a, b)
                moved = max(moved, abs(float(a) - float(b)) if name.endswith("_px") else 0.0)
            else:
                assert a == b, (name, a, b)
    assert moved > 1e-3, "the default tracker no longer takes the edge step"
    info_old = json.loads((old_dir / "tracking.json").read_text())
    info_new = json.loads((new_dir / "tracking.json").read_text())
    # the old tracker had no edge step (the field came with it)
    assert info_old.pop("edge_step", False) is False and info_new.pop("edge_step") is True
    _json_equal(info_old, info_new, "track/tracking.json (edge step)")


def test_every_command_writes_what_it_wrote_before(before_tree, tmp_path):
    old_dir, new_dir = tmp_path / "old", tmp_path / "new"
    old_dir.mkdir()
    new_dir.mkdir()
    for name, argv in _commands(tmp_path):
        out_old = _run(before_tree, old_dir, *argv)
        out_new = _run(None, new_dir, *argv)
        if "--json" in argv:
            _json_equal(json.loads(out_old), json.loads(out_new), f"stdout of {name}")
    compared = _compare_files(old_dir, new_dir)
    _run(None, new_dir, "track", "demo/twin", "--out", "track_edge_step", "--quiet",
         edge_step_default=True)
    _compare_edge_step_tracks(old_dir / "track", new_dir / "track_edge_step")
    for ssp in ("abu.ssp",):
        import zipfile
        with zipfile.ZipFile(old_dir / ssp) as a, zipfile.ZipFile(new_dir / ssp) as b:
            for member in ("SystemStructure.ssd", "resources/abu.ssv"):
                assert a.read(member) == b.read(member), member
    print(f"\n[unchanged] {len(compared)} CSV/JSON files compared field by field: "
          + ", ".join(compared))
    assert len(compared) >= 15
