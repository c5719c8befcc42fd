"""``abu identify``, ``abu design`` and ``abu next``: close the experiment loop.

:func:`register` adds the three commands to the ``abu`` parser (called from
:func:`abu.cli.main.build_parser`). Speeds in Hz only on the command line; SI inside. Errors are
AbuError / ParameterError naming the option or file (exit 2, nothing written); outputs go
through :func:`abu.cli.output_tx.output_folder` (all or nothing).
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any


from abu_model.errors import ParameterError

from abu.cli.plan_width import add_width_options, width_constants
from abu.cli.common import (add_figure_format, add_overwrite, camera_fps, finite, in_range, integer_range,
                            positive)

HZ = 2.0 * math.pi


def _jsonable(obj: Any) -> Any:
    from harness.experiments.results_io import to_jsonable
    return to_jsonable(obj)


def _dumps(obj: Any) -> str:
    return json.dumps(_jsonable(obj), indent=2, allow_nan=False) + "\n"


def load_drive_option(path: str | None):
    """The drive of ``--drive PATH`` (None without it); DriveFileError names file and field."""
    if path is None:
        return None
    from controller.drive import load_drive
    return load_drive(path)


def apply_drive_to_args(args: argparse.Namespace) -> None:
    """``--drive drive.json`` of ``abu simulate`` / ``abu render``: its zeta, omega_n and
    tau_motor replace ``--zeta``, ``--omega-n`` and ``--tau-motor`` (the PI reading is the
    integral one). A setpoint weight other than 1 is refused: the SpeedController FMU and the
    twin have none."""
    drive = load_drive_option(getattr(args, "drive", None))
    if drive is None:
        return
    if drive.is_tracking:
        raise ParameterError("--drive", args.drive, "a PI drive for a staircase (this one is a "
                             "tracking drive, which follows a profile: 'abu simulate --motion "
                             "profile' and 'abu render' take it with --profile profile.json)")
    if abs(drive.setpoint_weight - 1.0) > 1e-9:
        raise ParameterError("--drive", args.drive, "a drive without setpoint weighting "
                             f"(setpoint_weight 1, this one {drive.setpoint_weight:.4g}): the "
                             "simulated controller has none; identify with --model pi-lag")
    for name, absent in (("setpoint_tau_s", not drive.has_setpoint_filter),
                         ("sample_time_s", drive.sample_time is None)):
        if not absent:
            raise ParameterError("--drive", args.drive, f"a drive without {name} (the "
                                 "simulated controller is continuous and has no setpoint "
                                 "filter; only 'abu measure --kinematics drive-model' and "
                                 "'abu design' use it)")
    if getattr(args, "theta_ref", "integral") != "integral":
        raise ParameterError("--theta-ref", args.theta_ref, "integral with --drive")
    args.zeta, args.omega_n, args.tau_motor = drive.zeta, drive.omega_n, drive.tau_motor


# ---------------------------------------------------------------------------- identify
def _setpoints(args: argparse.Namespace):
    from controller.reference import Staircase

    from harness.planning.loop_response import as_setpoints
    from harness.planning.record_io import read_setpoints

    if args.setpoints is not None:
        if args.omega0_hz is not None or args.omega_end_hz is not None:
            raise ParameterError("--setpoints", args.setpoints,
                                 "either --setpoints or the staircase options, not both")
        return read_setpoints(args.setpoints)
    if args.omega0_hz is None or args.omega_end_hz is None:
        raise ParameterError("--setpoints", None, "a setpoint CSV, or --omega0-hz and "
                             "--omega-end-hz (with --t0, --te, --rounding) of the staircase")
    w0, we = finite("--omega0-hz", args.omega0_hz, "Hz"), finite("--omega-end-hz",
                                                                  args.omega_end_hz, "Hz")
    step = positive("--step-hz", args.step_hz, "Hz")
    te = positive("--te", args.te, "s")
    if math.floor(abs(we - w0) / step + 1e-9) < 1:
        raise ParameterError("--omega-end-hz", we, f"a speed at least --step-hz = {step:g} Hz "
                             f"away from --omega0-hz = {w0:g} Hz")
    return as_setpoints(Staircase(w0 * HZ, we * HZ, finite("--t0", args.t0, "s"), te, step * HZ,
                                  args.rounding))


def cmd_identify(args: argparse.Namespace) -> int:
    from harness.planning.identify import fit_drive
    from harness.planning.record_io import read_pulses, read_record

    if args.pulses is not None:
        if args.pulses_per_rev is None:
            raise ParameterError("--pulses-per-rev", None, "the number of pulses per revolution "
                                 "of the optical sensor (an integer >= 1) with --pulses")
        record = read_pulses(args.pulses, args.pulses_per_rev)
    else:
        record = read_record(args.record)
    result = fit_drive(record, _setpoints(args), args.model)
    if args.out:
        from abu.cli.output_tx import output_folder
        from harness.planning.plan_plots import plot_identify
        with output_folder(args.out, overwrite=args.overwrite) as tmp:
            (tmp / "drive.json").write_text(_dumps(result.drive.to_dict()), encoding="utf-8")
            if not args.no_plots:
                plot_identify(result, tmp / "fit", args.figure_format)
    if args.json:
        sys.stdout.write(_dumps(result.as_dict()))
        return 0
    d = result.drive
    print(f"model {d.model}: " + ", ".join(
        f"{n} = {d.value(n):.6g} [{lo:.6g}, {hi:.6g}] (95 %)" for n, (lo, hi) in d.ci95.items()))
    print(f"residuals: rms {result.check['rms']:.3g} "
          f"{'rad/s' if result.kind == 'omega' else 'rad'}, lag-1 autocorrelation "
          f"{result.check['lag1_autocorrelation']:.2f}: {result.check['message']}")
    rm = result.report_method
    if rm and rm.get("usable"):
        print(f"report's method (overshoot {100 * rm['overshoot']:.1f} %, settling "
              f"{rm['settling_time_s']:.3g} s): zeta = {rm['zeta']:.4g}, "
              f"omega_n = {rm['omega_n_rad_s']:.4g} rad/s")
    else:
        print("report's method: " + ("no single step in the record" if rm is None
                                     else rm["message"]))
    if args.out:
        print(f"wrote {Path(args.out) / 'drive.json'}"
              + ("" if args.no_plots else
                 f" and {Path(args.out) / ('fit.' + args.figure_format)}"))
    return 0


# ---------------------------------------------------------------------------- design, next
def _spec(args: argparse.Namespace, lo: float, hi: float, drive=None):
    from abu_model.params import BallParams

    from harness.planning.design import DesignSpec

    drive = load_drive_option(args.drive) if drive is None else drive
    kwargs: dict[str, Any] = {}
    if drive is not None:
        kwargs["drive"] = drive
    camera_fps("--fps", args.fps)
    integer_range("--frames", args.frames, 2, 100_000, "frames per record; the search "
                  "evaluates every candidate on the record's time grid")
    in_range("--speed-max-hz", args.speed_max_hz, 1.0, 1000.0, "Hz",
             "the search tries every whole-Hz start speed up to it")
    in_range("--step-hz", args.step_hz, 0.01, 10.0, "Hz", "the setpoint resolution; the "
             "report's setup has 1 Hz")
    try:
        return DesignSpec(
            width=width_constants(args, getattr(args, "summaries", None)),
            mu_lo=lo, mu_hi=hi,
            ball=BallParams(l=positive("--l", args.l, "m"), d=positive("--d", args.d, "m")),
            fps=args.fps, frames=args.frames,
            speed_min_hz=positive("--speed-min-hz", args.speed_min_hz, "Hz"),
            speed_max_hz=positive("--speed-max-hz", args.speed_max_hz, "Hz"),
            step_hz=positive("--step-hz", args.step_hz, "Hz"),
            edge_s=positive("--edge-s", args.edge_s, "s"),
            slip_window_s=positive("--slip-window-s", args.slip_window_s, "s", allow_zero=True),
            direction=-1 if args.direction == "cw" else 1, objective=args.objective, **kwargs)
    except ParameterError as exc:
        option = {"speed_max_hz": "--speed-max-hz", "edge_s": "--edge-s", "mu_lo": "--mu-range",
                  "mu_hi": "--mu-range"}.get(exc.parameter)
        raise exc if option is None else ParameterError(option, exc.value, exc.expected) from None


def _g(value: float | None, digits: int = 5) -> str:
    return "none" if value is None else f"{value:.{digits}g}"


def _describe_design(design, check) -> str:
    s = design.spec
    lines = [f"design for mu in [{s.mu_lo:.4g}, {s.mu_hi:.4g}] with the {s.drive.model} drive "
             f"(zeta {s.drive.zeta:.4g}, omega_n {s.drive.omega_n:.4g} rad/s, tau_motor "
             f"{s.drive.tau_motor:.3g} s):",
             f"  omega0 = {design.omega0_hz} Hz -> omega_end = {design.omega_end_hz:g} Hz, "
             f"t0 = {design.t0_s:g} s, te = {design.te_s:.4g} s, rounding {design.rounding}, "
             f"{s.step_hz:g} Hz steps; camera record [0, {s.record_s:.4f}] s",
             f"  first step: largest mu_req {design.first_step_max_mu_req:.4g} < mu_lo"
             + {None: "", True: "; holds at every corner of the drive's 95 % intervals",
                False: "; does NOT hold at every corner of the drive's 95 % intervals (identify "
                       "the drive more precisely)"}[design.ci_corners_hold],
             f"  {'mu [-]':>10} {'t_slip [s]':>10} {'mu_low [-]':>11} {'mu_high [-]':>11} "
             f"{'width [%]':>9}"]
    for k in range(0, design.mu.size, 3):
        lines.append(f"  {design.mu[k]:>10.4g} {design.t_slip_s[k]:>10.4f} "
                     f"{design.mu_low[k]:>11.4g} {design.mu_high[k]:>11.4g} "
                     f"{100 * design.relative_width[k]:>9.1f}")
    lines.append(f"  noise-free relative width: expected {100 * design.expected_width:.1f} %, "
                 f"worst {100 * design.worst_width:.1f} % (objective {s.objective}; slip located "
                 "within "
                 f"+-{1e3 * s.slip_window_s:g} ms); the report: "
                 + ", ".join(f"{k} {100 * v:.1f} %"
                             for k, v in design.as_dict()["report_relative_widths"].items()))
    lines += _describe_width(design)
    if check is not None:
        ok = all(r["first_step_stuck"] and r["slip_inside"] and r["brackets"] for r in check)
        lines.append("  co-simulation check (FMUs): " + "; ".join(
            f"mu {r['mu']:.4g}: slip at {_g(r['t_slip_s'])} s, [{_g(r['mu_low'])}, "
            f"{_g(r['mu_high'])}]" for r in check)
            + (" - all as designed" if ok else " - NOT as designed"))
    lines.append("  abu simulate " + " ".join(design.simulate_args()) + " --mu MU")
    lines.append("  abu render " + " ".join(design.render_args()) + " --mu MU")
    return "\n".join(lines)


def _pct(x: float | None) -> str:
    return "null bound" if x is None else f"{100 * x:.1f} %"


def _describe_width(design) -> list[str]:
    """Lines of the predicted ``abu measure`` width (expected and 90 % range)."""
    if design.width is None:
        return []
    w = design.as_dict()["width_prediction"]
    rows = w["table"]
    lines = [f"  predicted 'abu measure' width (hi - lo) / mid: expected {_pct(w['expected'])} "
             f"(90 % range {_pct(w['low90'])} - {_pct(w['high90'])}), worst "
             f"{_pct(w['worst_expected'])} over the range; at mu:"]
    for k in range(0, len(rows), 6):
        r = rows[k]
        lines.append(f"    mu {r['mu']:.4g}: {_pct(r['expected'])} ({_pct(r['low90'])} - "
                     f"{_pct(r['high90'])}; beta profile {_pct(r['profile'])}, lens prior "
                     f"+-{_pct(r['lens'])}, kinematic noise {_pct(r['kinematic_noise'])} "
                     "1 sigma)")
    lines.append(_assumed(w))
    changes = design.as_dict().get("what_if") or []
    if changes:
        lines.append(f"  what would narrow it (this staircase, predicted; now "
                     f"{_pct(w['expected'])}):")
        lines += [f"    {c['change']}: {_pct(c['expected'])}" for c in changes]
    return lines


def _assumed(w: dict) -> str:
    """The set-up the prediction assumed, and how to state yours."""
    cam = w["camera_noise"]
    typical = cam["noise_source"] == "typical"
    kin = {"savgol": "Savitzky-Golay kinematics (abu measure's default)",
           "drive-model": "drive-model kinematics"}[w["kinematics"]]
    return (f"  assumed: theta noise {cam['sigma_theta_rad']:.3g} rad, beta noise "
            f"{cam['sigma_beta_rad']:.3g} rad ("
            + ("a typical camera; yours: --noise-from SUMMARY.json ..." if typical
               else "from the summaries")
            + f"), lens prior {cam['theta_harmonic_rad']:.2g} rad ("
            + {"typical": "uncalibrated; --camera CAMERA.json, or a summary measured with "
                          "'abu measure --camera', gives the calibration's",
               "summaries": "from the summaries",
               "camera": cam["lens_note"]}[cam["lens_source"]]
            + f"), {kin}")


def _write_design(args, payload: dict, design, check, name: str) -> None:
    if not args.out:
        return
    from abu.cli.output_tx import output_folder
    from harness.planning.plan_plots import plot_design
    with output_folder(args.out, overwrite=args.overwrite) as tmp:
        (tmp / f"{name}.json").write_text(_dumps(payload), encoding="utf-8")
        if not args.no_plots:
            plot_design(design, tmp / name, check, args.figure_format)


def cmd_design(args: argparse.Namespace) -> int:
    from harness.planning.design import design_staircase
    from harness.planning.design_check import check_design

    drive = load_drive_option(args.drive)
    if drive is not None and drive.is_tracking:   # the report's ch. 6 drive: a profile
        from abu.cli.design_profile import cmd_design_profile
        return cmd_design_profile(args, drive)
    lo, hi = (finite("--mu-range", v) for v in args.mu_range)
    design = design_staircase(_spec(args, lo, hi, drive))
    check = None if args.no_check else check_design(design, fmu_dir=args.fmu_dir)
    payload = {**design.as_dict(), "check": check}
    _write_design(args, payload, design, check, "design")
    if args.json:
        sys.stdout.write(_dumps(payload))
    else:
        print(_describe_design(design, check))
    return 0


def cmd_next(args: argparse.Namespace) -> int:
    from controller.drive import drive_from_dict

    from harness.planning.design_check import check_design
    from abu.intervals_io import read_intervals
    from harness.planning.next_run import combine, propose_next

    drive = load_drive_option(args.drive)
    if drive is None or not drive.is_tracking:
        intervals = read_intervals(args.summaries)
    if args.drive is None:  # a drive recorded by 'abu measure --drive'
        recorded = next((i["drive"] for i in intervals if i["drive"]), None)
        drive = None if recorded is None else drive_from_dict(recorded, "drive in a summary")
    if drive is not None and drive.is_tracking:
        raise ParameterError("--drive", args.drive or "drive in a summary", "a PI drive: 'abu "
                             "next' plans staircases; for a tracking drive run 'abu design "
                             "--mu-range LO HI' on the combined interval")
    lo, hi = combine(intervals)
    proposal = propose_next(intervals, _spec(args, lo, hi, drive))
    check = None if args.no_check else check_design(proposal.design, fmu_dir=args.fmu_dir)
    payload = {**proposal.as_dict(), "check": check}
    _write_design(args, payload, proposal.design, check, "next")
    if args.json:
        sys.stdout.write(_dumps(payload))
        return 0
    print(f"{len(intervals)} interval(s); combined [{lo:.5g}, {hi:.5g}] (width {hi - lo:.3g})")
    print(_describe_design(proposal.design, check))
    print(f"  predicted combined interval after this run: worst width "
          f"{proposal.worst_combined_width:.3g} (now {hi - lo:.3g}), noise-free")
    c = proposal.combined_relative_width()
    print(f"  predicted combined relative width (hi - lo) / mid with 'abu measure' as predicted: "
          f"expected {_pct(c['expected'])} (90 % range {_pct(c['low90'])} - {_pct(c['high90'])}); "
          f"now {_pct((hi - lo) / (0.5 * (hi + lo)))}")
    return 0


# ---------------------------------------------------------------------------- parser
def _add_design_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--drive", default=None, help="drive.json of 'abu identify' (default: the "
                                                 "report's loop, zeta 0.5, omega_n 2.2 rad/s)")
    g = p.add_argument_group("setup and camera")
    g.add_argument("--speed-min-hz", type=float, default=2.0,
                   help="lowest |speed| [Hz] (default 2)")
    g.add_argument("--speed-max-hz", type=float, default=50.0,
                   help="highest |speed| [Hz] (default 50)")
    g.add_argument("--step-hz", type=float, default=1.0,
                   help="setpoint resolution [Hz] (default 1)")
    g.add_argument("--direction", choices=["cw", "ccw"], default="cw",
                   help="turning direction (default cw: negative speeds, the report's)")
    g.add_argument("--fps", type=float, default=4500.0, help="camera frame rate [frames/s]")
    g.add_argument("--frames", type=int, default=3072, help="frames per record (default 3072)")
    g.add_argument("--edge-s", type=float, default=0.05,
                   help="keep the slip this far from the record's ends [s] (default 0.05)")
    g.add_argument("--slip-window-s", type=float, default=0.004,
                   help="half-width of the time window in which a measurement locates the slip "
                        "[s] (default 0.004, as 'abu measure' on the twin)")
    g.add_argument("--objective", choices=["predicted", "expected", "worst"],
                   default="predicted",
                   help="minimise the mean width 'abu measure' is predicted to report over a "
                        "log-uniform prior on the range (default), or the noise-free mean or "
                        "largest width")
    add_width_options(g)
    g.add_argument("--l", type=float, default=1.15e-2, help="radius of the ball centre's path [m]")
    g.add_argument("--d", type=float, default=3.0e-3, help="ball diameter [m]")
    g = p.add_argument_group("output")
    g.add_argument("--no-check", action="store_true", help="skip the co-simulation check (FMUs)")
    g.add_argument("--fmu-dir", default=None, help="folder with the FMUs (built if missing)")
    g.add_argument("--out", default=None, help="write the JSON and a PNG plot into this folder")
    g.add_argument("--no-plots", action="store_true", help="no figure")
    add_figure_format(g)
    g.add_argument("--json", action="store_true", help="print JSON on stdout")
    add_overwrite(g)


def register(subparsers) -> None:
    """Add ``identify``, ``design`` and ``next`` to the ``abu`` subparsers."""
    from controller.drive import PI_MODELS

    p = subparsers.add_parser(
        "identify", help="fit the closed speed loop from a record of its response",
        description="Fit the setup's closed speed loop (zeta, omega_n[, tau_motor[, setpoint "
                    "weight]]) by least squares on the simulated response to the setpoint "
                    "sequence, with 95 % intervals, a residual check and the report's "
                    "overshoot/settling method beside it; writes drive.json and fit.png.")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--record", help="CSV with time_s and omega_rad_s or theta_rad "
                                      "(a tracks.csv works; time/theta/omega accepted too)")
    src.add_argument("--pulses", help="CSV with time_s: the optical sensor's pulse times")
    p.add_argument("--pulses-per-rev", type=int, default=None, help="pulses per revolution")
    p.add_argument("--setpoints", default=None,
                   help="CSV time_s,omega_ref_rad_s (each row: from this time on)")
    g = p.add_argument_group("staircase setpoints (instead of --setpoints)")
    g.add_argument("--omega0-hz", type=float, default=None, help="initial setpoint [Hz]")
    g.add_argument("--omega-end-hz", type=float, default=None, help="end of the inclined sine [Hz]")
    g.add_argument("--t0", type=float, default=0.0, help="start of the inclined sine [s]")
    g.add_argument("--te", type=float, default=1.0, help="duration of the inclined sine [s]")
    g.add_argument("--step-hz", type=float, default=1.0, help="setpoint resolution [Hz]")
    g.add_argument("--rounding", choices=["lead", "nearest", "trail"], default="lead")
    p.add_argument("--model", choices=PI_MODELS, default="pi-lag",
                   help="loop model (default pi-lag)")
    p.add_argument("--out", default=None, help="write drive.json and fit.png into this folder")
    p.add_argument("--no-plots", action="store_true", help="no fit.png")
    add_figure_format(p)
    p.add_argument("--json", action="store_true", help="print the drive as JSON on stdout")
    add_overwrite(p)
    p.set_defaults(func=cmd_identify)

    p = subparsers.add_parser(
        "design", help="plan the staircase for a prior range of mu",
        description="Choose omega0, omega_end, t0, te and the rounding so that for every mu in "
                    "the range the first step keeps the ball stuck, the slip falls inside the "
                    "camera's record away from its ends, and the predicted interval is "
                    "narrowest; co-simulates the design at the range's ends.")
    p.add_argument("--mu-range", type=float, nargs=2, required=True, metavar=("LO", "HI"),
                   help="prior range of mu [-]")
    _add_design_options(p)
    p.set_defaults(func=cmd_design)

    p = subparsers.add_parser(
        "next", help="propose the run that narrows the measured interval most",
        description="Combine the intervals of 'abu measure' (or 'abu simulate') summaries and "
                    "design the next staircase for the combined interval, with the predicted "
                    "combined interval after it.")
    p.add_argument("summaries", nargs="+", help="summary.json files of 'abu measure' or 'abu "
                                                "simulate', or CSV files with mu_low,mu_high")
    _add_design_options(p)
    p.set_defaults(func=cmd_next)
