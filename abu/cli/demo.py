"""``abu demo``: the report's staircase (both readings of the PI law) through the FMUs, then the
camera twin rendered, tracked and measured, all into one output folder (nothing is kept if a
step fails)."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from abu_model.params import PlantParams

from abu.cli.output_tx import output_folder
from harness.experiments.simulate_output import HZ, fmt_value, write_outputs

#: The report's eq. 4.9 bounds (thesis reading), printed beside ours.
REPORT_BOUNDS = {"mu_low": 2.63e-3, "mu_high": 4.14e-3}


class _StepFailed(Exception):
    """A step of the demo failed (its own message is printed): nothing is kept."""


def cmd_demo(args: argparse.Namespace) -> int:
    try:
        with output_folder(Path(args.out), overwrite=args.overwrite) as tmp:
            if _demo(tmp):
                raise _StepFailed
    except _StepFailed:
        return 2
    print(f"\nwrote everything into {args.out}")
    return 0


def _demo(out: Path) -> int:
    from fmus.build import build_fmus

    from harness.experiments.staircase import StaircaseExperiment, run_staircase

    fmus = build_fmus(out / "fmus")
    print(f"built {', '.join(p.name for p in fmus.values())}")
    print("report sec. 4.2.3: mu = 2.75e-3, omega0 = -17 Hz -> omega_end = -22 Hz, t0 = 0 s, "
          "te = 1 s, 1 Hz steps")
    for mode in ("integral", "thesis"):
        exp = StaircaseExperiment(PlantParams(), -17 * HZ, -22 * HZ, theta_ref_mode=mode)
        result = run_staircase(exp, fmus)
        s = result.summary
        written = write_outputs(result, out / mode)
        print(f"\n[{mode}] mu_low = {fmt_value(s['mu_low'])} [-] <= mu = {fmt_value(s['mu'])} "
              f"[-] < mu_high = {fmt_value(s['mu_high'])} [-]; "
              f"first slip at t = {fmt_value(s['t_slip'], 's', 6)}")
        if mode == "thesis":
            print(f"[{mode}] report eq. 4.9: mu_low = {REPORT_BOUNDS['mu_low']:g} [-], "
                  f"mu_high = {REPORT_BOUNDS['mu_high']:g} [-] (differences "
                  f"{100 * (s['mu_low'] / REPORT_BOUNDS['mu_low'] - 1):+.1f} %, "
                  f"{100 * (s['mu_high'] / REPORT_BOUNDS['mu_high'] - 1):+.1f} %)")
        print(f"[{mode}] wrote {len(written)} files into {mode}/")
    print("\nmeasurement chain on the synthetic camera twin (report sec. 5.3: -9 Hz -> -19 Hz in "
          "0.5 s, 4500 frames/s, true mu = 0.03): render, track, measure", flush=True)
    return _measure_twin(out, fmus)


def _measure_twin(out: Path, fmus) -> int:
    """Render the report's camera twin, then track and measure it (``abu render``, ``abu
    measure`` at their defaults)."""
    from measurement.pipeline import measure_recording, write_measurement
    from measurement.report.summary_text import describe_measurement
    from twin.report_twin import render_twin

    (out / "twin").mkdir()
    render_twin(out / "twin", fmu_dir=Path(next(iter(fmus.values()))).parent)
    print("wrote the twin recording (frames.tif, truth.csv, meta.json) into twin/", flush=True)
    result = measure_recording(out / "twin", log=lambda text: print(text, file=sys.stderr))
    (out / "measurement").mkdir()
    write_measurement(result, out / "measurement")
    print(describe_measurement(result.summary))
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``demo`` to the ``abu`` subcommands."""
    from abu.cli.common import add_overwrite

    p = sub.add_parser("demo", help="the report's staircase co-simulation and the measurement "
                                    "chain on a rendered recording",
                       description="Build the FMUs, co-simulate the report's staircase experiment "
                                   "(sec. 4.2.3: mu = 2.75e-3, -17 Hz -> -22 Hz in 1 s) with both "
                                   "theta_ref readings, print the bounds and write plots; then "
                                   "render the synthetic camera twin (sec. 5.3, mu = 0.03), track "
                                   "and measure it.")
    p.add_argument("--out", required=True, help="output folder")
    add_overwrite(p)
    p.set_defaults(func=cmd_demo)
