"""Human-readable text of the measurement summaries (what ``abu measure`` and ``abu
measure-summary`` print); the JSON files carry the same numbers."""
from __future__ import annotations


def fmt_value(v: float | None, spec: str = ".4g") -> str:
    return "none" if v is None else format(v, spec)


def describe_measurement(s: dict) -> str:
    """The lines ``abu measure`` prints for a summary.json (units in every line)."""
    conf = s.get("confidence")
    lines = [f"mu in [{fmt_value(s['mu_low'])}, {fmt_value(s['mu_high'])}]  ({s['status']})"
             + (f", {100 * conf:g} % confidence" if conf is not None else "")]
    mf, rm = s.get("model_fit"), s.get("running_max")
    if mf and rm:
        lines.append(f"  ball-model fit of beta: [{fmt_value(mf['mu_low'])}, {fmt_value(mf['mu_high'])}] "
                     f"({mf['status']}), slip onset {fmt_value(mf['t_slip'], '.4f')} s; mu_d = "
                     f"{fmt_value(s.get('mu_d'))} in [{fmt_value(s.get('mu_d_low'))}, "
                     f"{fmt_value(s.get('mu_d_high'))}]")
        if mf.get("lighting_models"):
            lines.append("  union of two lighting models: " + "; ".join(
                f"orders {m['harmonic_orders'][0]}-{m['harmonic_orders'][-1]} "
                f"[{fmt_value(m['mu_low'])}, {fmt_value(m['mu_high'])}]"
                for m in mf["lighting_models"]))
        lines.append(f"  report's running max: [{fmt_value(rm['mu_low'])}, "
                     f"{fmt_value(rm['mu_high'])}] ({rm['status']}"
                     + ("" if "no coverage" in rm["status"] else "; no coverage guarantee")
                     + ")")
    lines.append(f"  t_slip_low = {fmt_value(s['t_slip_low'], '.4f')} s (last surely stuck), "
                 f"t_slip_high = {fmt_value(s['t_slip_high'], '.4f')} s (first surely slipping)"
                 + (f", {100 * conf:g} % confidence" if conf is not None and mf else
                    " (the running max's, no coverage guarantee)"))
    if s.get("relative_width") is not None:
        lines.append(f"  relative width {100 * s['relative_width']:.1f} % (report, one run: 8.7 %)")
    for extra in (_kinematics_line(s.get("estimator") or {}), lens_line(s)):
        if extra:
            lines.append(extra)
    ea = s["error_analysis"]
    lines.append(f"  report's worst case ({100 * ea['e_omega']:g} % on omega, "
                 f"{100 * ea['e_omega_dot']:g} % on omega_dot): {100 * ea['e_mu_min']:+.1f} % / "
                 f"{100 * ea['e_mu_max']:+.1f} % -> [{fmt_value(ea['mu_low_widened'])}, "
                 f"{fmt_value(ea['mu_high_widened'])}]")
    mc = s.get("monte_carlo")
    if mc:
        for key in ("mu_low", "mu_high"):
            e = mc[key]
            if e.get("n_defined"):
                lines.append(f"  Monte Carlo ({mc['draws']} draws) {key}: 2.5/50/97.5 % = "
                             f"{e['p2.5']:.4g} / {e['p50']:.4g} / {e['p97.5']:.4g}")
    n = s["noise"]
    lines.append(f"  noise: theta {n['sigma_theta_rad']:.2e} rad, beta {n['sigma_beta_rad']:.2e} "
                 f"rad, omega_dot {n['sigma_omega_dot_rad_s2']:.3g} rad/s^2 (1 sigma); "
                 f"lost frames {s['lost_frames']['any']}")
    return "\n".join(lines)


def _kinematics_line(est: dict) -> str:
    """Where omega and omega_dot came from, and how to narrow the interval when they came from
    local smoothing (the default): the whole-record drive model, 1.8x narrower on the harsh
    family whether the loop is identified or not, and 1.7x with the staircase itself found
    from the record (benchmarks/bench_width_floor.py --find-staircase, seeds 7000-7023)."""
    if est.get("name") == "savgol" and est.get("model") is None:
        return ("  kinematics: local Savitzky-Golay fit; to narrow the interval state the "
                "staircase or profile the drive followed (--kinematics drive-model, with "
                "--drive or without), or, for one of the report's staircases whose figures "
                "you do not know, add --find-staircase (a few seconds more)")
    if est.get("model") == "accepted":
        return f"  kinematics: the drive model over the whole record (loop {est.get('loop')})"
    if est.get("model") == "refused":
        return f"  kinematics: drive model refused ({est.get('why')}); Savitzky-Golay used"
    return ""


def lens_line(s: dict) -> str:
    """Without a calibrated camera, what the lens prior (with the truncation bound) takes
    at the slip, and how to replace it: designed runs measured with a calibration were 1.5x
    narrower (benchmarks/bench_designed_runs.py --camera 30, docs/design.md)."""
    est, mf = s.get("estimator") or {}, s.get("model_fit") or {}
    bias = mf.get("kinematic_rel_bias_at_slip")
    if s.get("camera") or est.get("theta_harmonics_fitted") or not isinstance(
            bias, (int, float)) or not bias > 0:
        return ""
    return (f"  lens: uncalibrated; its prior bound on theta's harmonic (with the truncation "
            f"bound) takes +-{100 * bias:.1f} % of mu at the slip; a chessboard calibration "
            "(abu calibrate-camera, then --camera camera.json) replaces it by the "
            "calibration's own")


def describe_combined(r: dict) -> str:
    """The lines ``abu measure-summary`` prints for a combined summary."""
    lines = [f"{r['n_records']} intervals ({r['n_complete']} with both bounds)"]
    u = r["union_hull"]
    lines.append(f"  contained in at least one interval: [{fmt_value(u[0])}, {fmt_value(u[1])}]")
    m = r["majority_range"]
    lines.append(f"  contained in more than half: "
                 f"{'none' if m is None else '[' + fmt_value(m[0]) + ', ' + fmt_value(m[1]) + ']'}")
    c = r["common_range"]
    lines.append("  contained in all: "
                 + ("none" if c is None else f"[{fmt_value(c[0])}, {fmt_value(c[1])}]"))
    t = r["turnbull"]
    lines.append(f"  Turnbull NPMLE median in [{fmt_value(t['median'][0])}, {fmt_value(t['median'][1])}]")
    return "\n".join(lines)
