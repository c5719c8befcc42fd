"""``abu demo``: the report's staircase (both readings of the PI law) through the FMUs, then the
camera twin rendered, tracked and measured, all into one output folder (nothing is kept if a
step fails)."""
from __future__ import annotations

import argparse
from pathlib import Path

from abu_model.params import PlantParams

from .output_tx import output_folder
from .simulate_output import HZ, fmt_value, write_outputs

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

    from .cli import main
    from .experiments import StaircaseExperiment, run_staircase

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
    # --quiet: render would name the run's temporary folder; the demo names the final one.
    if main(["render", "--out", str(out / "twin"), "--quiet"]):
        return 2
    print("wrote the twin recording (frames.tif, truth.csv, meta.json) into twin/", flush=True)
    return main(["measure", str(out / "twin"), "--out", str(out / "measurement")])
