"""Write every figure the commands draw into one folder, for looking at them (issue 20).

    python benchmarks/make_figures.py --out figs [--figure-format png|pdf|svg] [--quick]

Runs, in this process and in this order: ``abu render`` (the report's twin, 3072 frames; with
``--quick`` 1800) and ``abu measure`` on it (``beta``, ``kinematics``), ``abu measure-summary``
on that summary and eleven more intervals drawn like the report's twelve (``histogram``),
``abu simulate`` (the report's staircase, sec. 4.2.3: ``omega``, ``omega_dot``, ``beta``,
``beta_dot``, ``mu_req``), ``abu design --mu-range 0.02 0.04`` (``design``, with its
co-simulation check), ``abu next`` on the measured summary (``next``, no check) and
``abu identify`` on a simulated optical-sensor record of the twin's drive (``fit``). Each
figure's layout is checked (:func:`abu_model.figure_files.layout_problems`) and its problems,
if any, printed. The FMUs are built into ``OUT/fmus``. Nothing is committed: the README
describes two of these figures.

``make_all`` is what ``tests/test_figures.py`` runs, with a tracks CSV instead of a render.
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

HZ = 2.0 * math.pi
#: The twin's drive (zeta, omega_n [rad/s], tau_motor [s]) for the identify record.
DRIVE = (0.7, 12.0, 0.02)


def _run(argv: list[str]) -> None:
    from abu.cli.main import main

    code = main(argv)
    if code != 0:
        raise SystemExit(f"abu {' '.join(argv)} exited with {code}")


def _intervals_csv(path: Path, n: int = 11, seed: int = 5) -> Path:
    """``n`` intervals like the report's (fig. 5.11: mu 0.024-0.035), seeded."""
    rng = np.random.default_rng(seed)
    mid = rng.uniform(0.026, 0.032, n)
    half = rng.uniform(0.0012, 0.003, n)
    rows = ["mu_low,mu_high"] + [f"{m - h:.5f},{m + h:.5f}" for m, h in zip(mid, half)]
    path.write_text("\n".join(rows) + "\n")
    return path


def _identify_inputs(folder: Path) -> tuple[Path, Path]:
    """An optical-sensor record (4 pulses a revolution, 50 us jitter) of a 5 -> 20 Hz step of
    the twin's drive, and its setpoints."""
    from harness.planning.loop_response import Setpoints, response

    zeta, wn, tau = DRIVE
    sp = Setpoints((0.1,), (5 * HZ, 20 * HZ))
    t = np.linspace(0.0, 1.3, 100001)
    angle = response(sp, t, zeta, wn, tau).theta
    angle = angle - angle[0]
    k = np.arange(1, int(angle[-1] / (2 * math.pi / 4)))
    rng = np.random.default_rng(3)
    tp = np.interp(k * 2 * math.pi / 4, angle, t) + rng.normal(0.0, 50e-6, k.size)
    pulses = folder / "pulses.csv"
    pulses.write_text("time_s\n" + "\n".join(f"{v:.7f}" for v in np.sort(tp)) + "\n")
    setpoints = folder / "setpoints.csv"
    setpoints.write_text(f"time_s,omega_ref_rad_s\n0.0,{5 * HZ!r}\n0.1,{20 * HZ!r}\n")
    return pulses, setpoints


def make_all(out: Path, figure_format: str = "png", *, fmu_dir: Path,
             tracks_csv: Path | None = None, frames: int = 3072,
             design_check: bool = True) -> dict[str, list[Path]]:
    """Every command's figures into ``out/<command>/``; returns {command: [figure paths]}."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    fmt = ["--figure-format", figure_format]
    fmus = ["--fmu-dir", str(fmu_dir)]
    inputs = out / "inputs"
    inputs.mkdir(exist_ok=True)
    if tracks_csv is None:
        _run(["render", "--out", str(inputs / "twin"), "--frames", str(frames), "--quiet",
              "--overwrite", *fmus])
        _run(["measure", str(inputs / "twin"), "--out", str(out / "measure"), "--quiet",
              "--overwrite", *fmt])
    else:
        _run(["measure", str(tracks_csv), "--tracks", "--out", str(out / "measure"), "--quiet",
              "--overwrite", *fmt])
    summary = out / "measure" / "summary.json"
    _run(["measure-summary", str(summary), str(_intervals_csv(inputs / "intervals.csv")),
          "--out", str(out / "measure-summary"), "--overwrite", *fmt])
    _run(["simulate", "--out", str(out / "simulate"), "--overwrite", *fmus, *fmt])
    # --fmu-dir serves the co-simulation check only: with --no-check it is refused
    _run(["design", "--mu-range", "0.02", "0.04", "--out", str(out / "design"), "--overwrite",
          *fmt] + (fmus if design_check else ["--no-check"]))
    _run(["next", str(summary), "--no-check", "--out", str(out / "next"), "--overwrite", *fmt])
    pulses, setpoints = _identify_inputs(inputs)
    _run(["identify", "--pulses", str(pulses), "--pulses-per-rev", "4", "--setpoints",
          str(setpoints), "--out", str(out / "identify"), "--overwrite", *fmt])
    suffix = "." + figure_format
    return {cmd: sorted(p for p in (out / cmd).iterdir() if p.suffix == suffix)
            for cmd in ("measure", "measure-summary", "simulate", "design", "next", "identify")}


def main(argv: list[str] | None = None) -> int:
    import abu_model.figure_files as ff
    from fmus.build import build_fmus

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", required=True, help="output folder")
    ap.add_argument("--figure-format", choices=ff.FIGURE_FORMATS, default="png")
    ap.add_argument("--quick", action="store_true", help="a 1800-frame twin")
    args = ap.parse_args(argv)
    out = Path(args.out)
    fmu_dir = Path(next(iter(build_fmus(out / "fmus").values()))).parent
    problems: list[str] = []
    original = ff.save_figure

    def checked(fig, path, figure_format="png"):
        problems.extend(f"{Path(path).name}: {p}" for p in ff.layout_problems(fig))
        return original(fig, path, figure_format)

    # every module that saves a figure looks save_figure up in its own namespace
    import harness.experiments.plots as hp
    import measurement.report.plots as mp
    for module in (ff, hp, mp):
        module.save_figure = checked
    figures = make_all(out, args.figure_format, fmu_dir=fmu_dir,
                       frames=1800 if args.quick else 3072)
    for cmd, paths in figures.items():
        print(f"abu {cmd}: " + ", ".join(str(p) for p in paths))
    print("layout problems: " + ("; ".join(problems) if problems else "none"))
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
