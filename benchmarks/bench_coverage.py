"""Coverage of the stated confidence interval on mu over the harsh twin's random family.

For each seed: ``twin.scenario.random_scenario(seed)`` (the family of ``abu render
--scenario random``: drives, optics, lighting incl. the two-reflection lighting, mu in
[0.005, 0.06], mu_d/mu in [0.6, 1]) is simulated and rendered to raw frames (``.npy``), then
``abu measure`` runs on the frames in this process (default settings, ``--no-plots``; two-
reflection recordings with ``--ball-reflections 2`` as their ``meta.json`` says). Printed:

* coverage of the stated 95 % interval, number of intervals missing mu by more than 2 % of mu,
  median / 90th percentile relative width, null-bound statuses; the same for the report's
  running-max interval (``running_max`` in summary.json) for comparison;
* mu_d: coverage of its interval and median relative error of its estimate;
* the acceleration bias at the slip: the estimator applied to the *true* theta (no noise) minus
  the true omega_dot at the first slip frame, against the recording's 1-sigma noise bar of
  omega_dot (and against noise + truncation bound);
* what "no miss by more than 2 %" asks: the misses calibrated 95 % intervals of the reported
  widths would make (mu's error Gaussian, sigma = half-width / 1.96), and the spread of mu's
  position in the reported intervals (1 if calibrated, below 1 if conservative);
* seconds per recording (render and measure apart);
* with ``--camera``: per recording the chessboard views of its optics are rendered
  (``twin.calibration_target``), ``abu calibrate-camera`` fits the lens and ``abu
  measure --camera`` undistorts the tracks; printed beside: median |k1 error|, reprojection
  RMS, seconds, and the first harmonic of theta's error (measured - truth) against the prior
  bound the measurement used (the calibration's, or the family's 8e-4 rad without camera).

Run (one process, nice; the 220-recording run took 12 minutes on the shared machine)::

    nice python benchmarks/bench_coverage.py --n 200 --out /tmp/cov
    nice python benchmarks/bench_coverage.py --n 200 --camera --out /tmp/cov_cam
    nice python benchmarks/bench_coverage.py --n 200 --no-edge-step  # contour fits alone
    nice python benchmarks/bench_coverage.py --n 200 --edge-step  # the edge step on every disk
    nice python benchmarks/bench_coverage.py --n 100 --first 2000 --two-spot 20 --alt-two-spot 40 \
        --out /tmp/cov_unseen   # an unseen slice, two-reflection recordings of both models
                                # (all from the raw frames, the marker finder included;
                                # --alt-seeds-given: the second model's from the true seeds)
    nice python benchmarks/bench_coverage.py --seeds 3054,3064 --two-spot 0 --out D --keep D
    python benchmarks/bench_coverage.py --reanalyse D   # the kept tracks, current analysis
    python benchmarks/bench_coverage.py --reanalyse D --lighting-models two   # both lighting
                                                        # models' union (lighting_models)
"""
from __future__ import annotations

import argparse
import csv
import io
import json
import math
import os
import sys
import tempfile
import time
from contextlib import redirect_stderr, redirect_stdout
from dataclasses import replace
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from abu.cli.main import main as abu_main  # noqa: E402
from measurement.kinematics import estimators as kin_mod  # noqa: E402
from measurement.inference.analysis import AnalysisOptions  # noqa: E402
from twin import lighting_alt  # noqa: E402
from twin.calibration_target import DEFAULT_VIEWS  # noqa: E402
from lens_calibration import calibrate  # noqa: E402
from measurement.inference.infer_mu import InferenceOptions  # noqa: E402
from twin.scenario import (random_scenario, render_scenario_frames,  # noqa: E402
                                  simulate_scenario)

#: Options added to every ``abu measure`` of the rendered recordings (``--edge-step``,
#: ``--no-edge-step``).
EXTRA_MEASURE_ARGS: list[str] = []
#: Analysis options added to every ``abu measure``, also of kept tracks (``--lighting-models``).
ANALYSIS_ARGS: list[str] = []
#: ``--alt-seeds-given``: the second highlight model's recordings start from the true seeds
#: (default: the marker finder's, the whole chain from the raw frames).
ALT_SEEDS_GIVEN = False
#: theta's harmonic prior without a camera file (the family prior).
THETA_PRIOR_DEFAULT = InferenceOptions().theta_harmonic_rad


def theta_first_harmonic(times: np.ndarray, theta: np.ndarray, theta_true: np.ndarray) -> float:
    """Amplitude [rad] of the first harmonic of the measured theta's error (regressed with
    1, t, t^2, as benchmarks/bench_kinematic_error.py does)."""
    tc = times - times.mean()
    design = np.column_stack([np.ones_like(tc), tc, tc ** 2, np.sin(theta_true),
                              np.cos(theta_true)])
    coef = np.linalg.lstsq(design, theta - theta_true, rcond=None)[0]
    return float(np.hypot(*coef[3:]))


#: ``--faint-two-spot``: the second highlight model's ball faded towards the plane by a factor
#: drawn in this range (twin.lighting_alt.faded): outlines 1-2 noise sigma above the plane.
FAINT_FACTORS = (0.2, 0.6)


def scenario(seed: int, size: int, lighting: str | None):
    """The recording's scenario; ``two_spot_faint``: the second highlight model's, its ball
    faded by a factor in :data:`FAINT_FACTORS` drawn from the seed."""
    if lighting != "two_spot_faint":
        return random_scenario(seed, size=size, lighting=lighting)
    scn = random_scenario(seed, size=size, lighting="two_spot_alt")
    factor = np.random.default_rng([seed, 0xFA17]).uniform(*FAINT_FACTORS)
    return replace(scn, lighting=lighting_alt.faded(scn.lighting, float(factor)))


def one(seed: int, work: Path, size: int, lighting: str | None, views: int = 0,
        keep: Path | None = None) -> dict:
    """Render and measure one recording; the row of the results table (``views`` > 0: with
    a camera calibrated on that many chessboard views, ``abu measure --camera``; ``keep``: a
    folder for the tracks and the true state, to re-analyse with ``--reanalyse``)."""
    t0 = time.perf_counter()
    scn = scenario(seed, size, lighting)
    state, pos = simulate_scenario(scn)
    frames = render_scenario_frames(scn, state, pos)
    rec = work / f"rec{seed}.npy"
    np.save(rec, frames)
    t1 = time.perf_counter()
    out = work / f"m{seed}"
    refl = int(scn.lighting.reflections)
    args = ["measure", str(rec), "--out", str(out), "--overwrite", "--quiet", "--no-plots",
            "--fps", repr(scn.fps), "--l", repr(scn.ball.l), "--d", repr(scn.ball.d)]
    args += EXTRA_MEASURE_ARGS + ANALYSIS_ARGS
    if keep is not None:
        keep.mkdir(parents=True, exist_ok=True)
        np.savez(keep / f"state{seed}.npz", times=scn.times, l=scn.ball.l, d=scn.ball.d,
                 **state)
    cal = {}
    if views:
        cam, cal = calibrate(scn, work, views)
        args += ["--camera", str(cam)]
        t1 = time.perf_counter()
    if refl == 2:
        args += ["--ball-reflections", "2"]
    if lighting in ("two_spot_alt", "two_spot_faint") and ALT_SEEDS_GIVEN:
        # --alt-seeds-given: the tracker starts from the true frame-0 positions (what a user
        # gives with --seeds), as before the marker finder read the second model's dark balls
        from measurement.imaging.markers import format_seeds
        args += ["--seeds", format_seeds(np.stack([pos["centre"][0], pos["cd"][0],
                                                   pos["ball"][0]]))]
    err = io.StringIO()
    with redirect_stdout(io.StringIO()), redirect_stderr(err):
        status = abu_main(args)
    t2 = time.perf_counter()
    row = {"seed": seed, "reflections": refl, "mu": scn.ball.mu, "mu_d": scn.ball.mu_dynamic,
           "drive": scn.drive.kind, "tau_motor_s": scn.drive.tau_motor,
           "setpoint_tau_s": scn.drive.setpoint_tau,
           "render_s": t1 - t0, "measure_s": t2 - t1, "exit": status, **cal}
    rec.unlink()
    if keep is not None and (out / "tracks.csv").exists():
        (keep / f"tracks{seed}.csv").write_bytes((out / "tracks.csv").read_bytes())
    return measured_row(row, status, err, out, scn.times, state)


def measured_row(row: dict, status: int, err: io.StringIO, out: Path, times: np.ndarray,
                 state: dict) -> dict:
    """``row`` completed from ``abu measure``'s output folder ``out`` and the true state."""
    if status != 0:
        row["error"] = err.getvalue().strip().splitlines()[-1:] or ["?"]
        return row
    s = json.loads((out / "summary.json").read_text())
    row.update({k: s.get(k) for k in ("mu_low", "mu_high", "status", "mu_d_low", "mu_d_high",
                                      "confidence", "relative_width")})
    row["mu_d_hat"] = s.get("mu_d")
    row["tracking_method"] = (s.get("input") or {}).get("method")
    mf = s.get("model_fit") or {}
    row["model_low"] = mf.get("mu_low", s.get("mu_low"))
    row["model_high"] = mf.get("mu_high", s.get("mu_high"))
    row.update({k: mf.get(k) for k in ("kinematic_rel_sigma_at_slip", "kinematic_rel_bias_at_slip",
                                       "profile_mu_low", "profile_mu_high", "ar1_rho",
                                       "t_slip")})
    row["t_slip_true"] = float(state["switches"][0]) if len(state["switches"]) else None
    if "lighting_disagreement_chi2" in mf:       # --lighting-models two
        row["lighting_chi2"] = mf["lighting_disagreement_chi2"]
        row["lighting_union"] = "lighting_models" in mf
    cam_info = s.get("camera") or {}
    row["theta_prior_rad"] = (cam_info.get("theta_harmonic_prior") or {}).get(
        "theta_harmonic_rad", THETA_PRIOR_DEFAULT)
    rm = s["running_max"]
    row.update({"rm_low": rm["mu_low"], "rm_high": rm["mu_high"], "rm_status": rm["status"],
                "t_slip_low": s.get("t_slip_low"), "t_slip_high": s.get("t_slip_high"),
                "band_t_slip_low": ((s.get("onset_bracket") or {}).get("band") or {}).get(
                    "t_slip_low"),
                "band_t_slip_high": ((s.get("onset_bracket") or {}).get("band") or {}).get(
                    "t_slip_high"),
                "rm_t_slip_low": rm.get("t_slip_low"), "rm_t_slip_high": rm.get("t_slip_high")})
    # acceleration bias at the first slip frame: the estimator on the true theta
    slip = np.flatnonzero(state["mode"] != 0)
    if slip.size:
        i = int(slip[0])
        opt = AnalysisOptions()
        clean = kin_mod.savgol_kinematics(times, state["theta"], window_s=opt.sg_window_s,
                                          polyorder=opt.sg_polyorder, sigma_theta=1e-15)
        with open(out / "kinematics.csv", newline="") as fh:
            kin = list(csv.DictReader(fh))
        sig = float(kin[i]["sigma_omega_dot_rad_s2"])
        bnd = float(kin[i]["bias_omega_dot_rad_s2"] or 0.0)
        th = np.array([float(k["theta_rad"]) for k in kin])
        row["theta_a1_rad"] = theta_first_harmonic(times, th, state["theta"])
        row.update({"slip_frame": i, "acc_bias": float(clean.omega_dot[i] - state["alpha"][i]),
                    "acc_sigma": sig, "acc_bound": bnd, "acc_true": float(state["alpha"][i])})
    return row


def reanalyse(folder: Path, work: Path) -> list[dict]:
    """The rows of ``folder/results.jsonl`` measured again from the tracks kept there
    (``--keep``: ``abu measure --tracks``, the current analysis on the same tracking)."""
    rows = []
    for line in open(folder / "results.jsonl"):
        row = json.loads(line)
        tracks = folder / f"tracks{row['seed']}.csv"
        if row.get("exit") != 0 or not tracks.exists():
            rows.append(row)
            continue
        st = dict(np.load(folder / f"state{row['seed']}.npz"))
        out = work / f"m{row['seed']}"
        keep = {k: row[k] for k in ("seed", "reflections", "mu", "mu_d", "drive", "tau_motor_s",
                                    "setpoint_tau_s", "render_s", "forced_lighting")}
        t1 = time.perf_counter()
        err = io.StringIO()
        with redirect_stdout(io.StringIO()), redirect_stderr(err):
            status = abu_main(["measure", str(tracks), "--tracks", "--out", str(out),
                               "--overwrite", "--quiet", "--no-plots", "--l",
                               repr(float(st["l"])), "--d", repr(float(st["d"])),
                               # how the tracked ball looked (the default lighting models
                               # follow it, as when the recording was measured)
                               *(["--ball-reflections", "2"] if row["reflections"] == 2
                                 else []), *ANALYSIS_ARGS])
        keep.update({"measure_s": time.perf_counter() - t1, "exit": status})
        rows.append(measured_row(keep, status, err, out, st["times"], st))
        r = rows[-1]
        print(f"seed {r['seed']} mu {r['mu']:.5f} -> [{r.get('mu_low')}, {r.get('mu_high')}] "
              f"{r.get('status', r.get('error'))}", flush=True)
    return rows


def covered(lo: float | None, hi: float | None, mu: float) -> bool:
    return (lo is None or lo <= mu) and (hi is None or mu <= hi)


def miss(lo: float | None, hi: float | None, mu: float) -> float:
    """Relative distance of mu outside [lo, hi] (0 inside)."""
    out = 0.0
    if lo is not None and mu < lo:
        out = (lo - mu) / mu
    if hi is not None and mu > hi:
        out = (mu - hi) / mu
    return out


def calibrated_misses(rows: list[dict], lo_k: str = "mu_low", hi_k: str = "mu_high",
                      margin: float = 0.02, level: float = 0.95) -> tuple[float, float, int]:
    """What "no miss by more than ``margin``" asks of intervals of these widths.

    A calibrated interval at ``level`` (mu's error Gaussian, the interval centre +- z sigma)
    misses mu by more than ``margin`` of mu with probability 2 Phi(-(z + margin mu / sigma)):
    the narrower the interval, the likelier a miss beyond a fixed margin. Returns (the expected
    number of such misses over the rows with both bounds, the standard deviation of mu's
    position in them, (mu - centre) / sigma, 1 for calibrated intervals and below 1 for
    conservative ones, the number of rows used).
    """
    from statistics import NormalDist
    nd = NormalDist()
    z = nd.inv_cdf(0.5 + 0.5 * level)
    both = [r for r in rows if r.get(lo_k) is not None and r.get(hi_k) is not None
            and r[hi_k] > r[lo_k]]
    if not both:
        return float("nan"), float("nan"), 0
    mu = np.array([r["mu"] for r in both])
    lo = np.array([r[lo_k] for r in both])
    hi = np.array([r[hi_k] for r in both])
    sigma = 0.5 * (hi - lo) / z
    expected = float(sum(2.0 * nd.cdf(-(z + margin * m / s)) for m, s in zip(mu, sigma)))
    return expected, float(np.std((mu - 0.5 * (lo + hi)) / sigma)), len(both)


def onset_report(ok: list[dict]) -> None:
    """Coverage of the true first slip onset by [t_slip_low, t_slip_high] (a null end is no
    claim: counted apart, and only finite brackets count as hits)."""
    for name, lo_k, hi_k in (("onset bracket (summary t_slip_low/t_slip_high)", "t_slip_low",
                              "t_slip_high"),
                             ("band bracket (summary onset_bracket.band)", "band_t_slip_low",
                              "band_t_slip_high"),
                             ("running max's bracket (summary running_max)", "rm_t_slip_low",
                              "rm_t_slip_high")):
        sel = [r for r in ok if r.get("t_slip_true") is not None and lo_k in r]
        if not sel:
            continue
        both = [r for r in sel if r[lo_k] is not None and r[hi_k] is not None]
        hit = [r[lo_k] <= r["t_slip_true"] <= r[hi_k] for r in both]
        late = [1e3 * (r[lo_k] - r["t_slip_true"]) for r in sel
                if r[lo_k] is not None and r[lo_k] > r["t_slip_true"]]
        early = [1e3 * (r["t_slip_true"] - r[hi_k]) for r in sel
                 if r[hi_k] is not None and r[hi_k] < r["t_slip_true"]]
        wid = [1e3 * (r[hi_k] - r[lo_k]) for r in both]
        print(f"  {name}: {len(sel)} recordings with a true slip, both ends in {len(both)}; "
              f"contains the true onset in {100 * np.mean(hit) if hit else float('nan'):.1f} % "
              f"of those; t_slip_low after the onset in {len(late)} (worst "
              f"{max(late) if late else 0.0:.1f} ms), t_slip_high before it in {len(early)} "
              f"(worst {max(early) if early else 0.0:.1f} ms); bracket width median "
              f"{np.median(wid) if wid else float('nan'):.1f} ms")


def report(rows: list[dict], label: str) -> None:
    ok = [r for r in rows if r.get("exit") == 0]
    print(f"\n== {label}: {len(rows)} recordings, {len(ok)} measured "
          f"({len(rows) - len(ok)} refused or failed)")
    if not ok:
        return
    methods = [r["tracking_method"] for r in ok if r.get("tracking_method")]
    if any("+" in m for m in methods):   # the two-reflection tracker says how it read the ball
        print("  ball tracked by: " + ", ".join(
            f"{m.split('+')[-1]} {methods.count(m)}" for m in sorted(set(methods))))
    judged = [r for r in ok if "lighting_union" in r]
    if judged:
        print(f"  second lighting model's set computed (and joined) in "
              f"{100 * np.mean([r['lighting_union'] for r in judged]):.1f} % of {len(judged)}")
    for r in ok:
        # hull of the two (AnalysisOptions.combine="hull", the default reported interval)
        for k, f, a, b in (("hull_low", min, "model_low", "rm_low"),
                           ("hull_high", max, "model_high", "rm_high")):
            va, vb = r.get(a, r.get(k.replace("hull", "mu"))), r[b]
            r[k] = None if va is None or vb is None else f(va, vb)
    for name, lo_k, hi_k in (("reported (summary mu_low/mu_high)", "mu_low", "mu_high"),
                             ("model-based set alone (summary model_fit)", "model_low",
                              "model_high"),
                             ("report's running max (summary running_max)", "rm_low",
                              "rm_high"),
                             ("hull of model and running max", "hull_low", "hull_high")):
        if any(lo_k not in r for r in ok):
            continue
        cov = np.mean([covered(r[lo_k], r[hi_k], r["mu"]) for r in ok])
        misses = [miss(r[lo_k], r[hi_k], r["mu"]) for r in ok]
        widths = [(r[hi_k] - r[lo_k]) / (0.5 * (r[hi_k] + r[lo_k])) for r in ok
                  if r[lo_k] is not None and r[hi_k] is not None]
        both = len(widths)
        # how close the nearest bound comes to mu (negative: a miss), relative to mu
        margins = [(r["mu"] - r[lo_k]) / r["mu"] for r in ok if r[lo_k] is not None] + \
            [(r[hi_k] - r["mu"]) / r["mu"] for r in ok if r[hi_k] is not None]
        # a null bound is no claim, not a hit: the share of finite intervals holding mu
        hold = np.mean([r[lo_k] is not None and r[hi_k] is not None
                        and r[lo_k] <= r["mu"] <= r[hi_k] for r in ok])
        print(f"  {name}: coverage {100 * cov:.1f} % ({len(ok)}; finite and holding mu: "
              f"{100 * hold:.1f} %), missing mu by > 2 %: "
              f"{sum(m > 0.02 for m in misses)}, worst miss {100 * max(misses):.1f} %, "
              f"closest bound {100 * min(margins) if margins else float('nan'):.1f} % from mu; "
              f"both bounds in {both}: relative width median "
              f"{100 * np.median(widths) if widths else float('nan'):.1f} %, 90th percentile "
              f"{100 * np.percentile(widths, 90) if widths else float('nan'):.1f} %")
    expected, spread, n_both = calibrated_misses(ok)
    print(f"  for comparison, calibrated 95 % intervals of the reported widths (mu's error "
          f"Gaussian, sigma = half-width / 1.96) would miss mu by > 2 % about {expected:.1f} "
          f"times in these {n_both} ({100 * expected / max(n_both, 1):.1f} %); mu's position "
          f"in the reported intervals, (mu - centre) / sigma, has spread {spread:.2f} (1 if "
          f"calibrated, below 1 if conservative)")
    # Width by drive class: where a setpoint step reaches the acceleration through almost no
    # lag (staircase, torque lag + setpoint filter < 5 ms: alpha rises within a fraction of
    # the 36 ms kinematic window) no method can beat the jump's [mu_req(t-), mu_req(t+)];
    # elsewhere alpha is continuous on the window's scale.
    def jumping(r: dict) -> bool:
        return (str(r["drive"]).startswith("staircase")
                and r["tau_motor_s"] + (r["setpoint_tau_s"] or 0.0) < 5e-3)

    for cls, pick in (("jumping (staircase, lag + setpoint filter < 5 ms)", True),
                      ("continuous (all other drives)", False)):
        sel = [r for r in ok if "setpoint_tau_s" in r and jumping(r) == pick]
        ws = [(r["mu_high"] - r["mu_low"]) / (0.5 * (r["mu_high"] + r["mu_low"])) for r in sel
              if r["mu_low"] is not None and r["mu_high"] is not None]
        if sel:
            print(f"  reported interval, {cls}: {len(sel)} recordings, coverage "
                  f"{100 * np.mean([covered(r['mu_low'], r['mu_high'], r['mu']) for r in sel]):.1f}"
                  f" %, relative width median "
                  f"{100 * np.median(ws) if ws else float('nan'):.1f} %, 90th percentile "
                  f"{100 * np.percentile(ws, 90) if ws else float('nan'):.1f} %")
    onset_report(ok)
    nulls: dict[str, int] = {}
    for r in ok:
        if r["status"] != "ok":
            nulls[r["status"]] = nulls.get(r["status"], 0) + 1
    print(f"  statuses other than ok: {nulls or 'none'}")
    # the model's set disjoint from the running max (status "check: ..."), from the rows
    # themselves, so that runs from before the status existed are counted the same way
    disjoint = [r for r in ok if None not in (r["mu_low"], r["mu_high"], r.get("rm_low"),
                                              r.get("rm_high"))
                and (r["mu_high"] < r["rm_low"] or r["mu_low"] > r["rm_high"])]
    misses = sum(not covered(r["mu_low"], r["mu_high"], r["mu"]) for r in disjoint)
    print(f"  model's set disjoint from the running max ('check' status): {len(disjoint)} of "
          f"{len(ok)}, {misses} of them missing mu (seeds "
          f"{[r['seed'] for r in disjoint]})")
    d = [r for r in ok if r["mu_d_low"] is not None]
    if d:
        cov_d = np.mean([r["mu_d_low"] <= r["mu_d"] <= r["mu_d_high"] for r in d])
        err_d = [abs(r["mu_d_hat"] - r["mu_d"]) / r["mu_d"] for r in d
                 if r["mu_d_hat"] is not None]
        print(f"  mu_d: interval in {len(d)}, coverage {100 * cov_d:.1f} %, median relative "
              f"error of the estimate {100 * np.median(err_d):.1f} %")
    a = [r for r in ok if "acc_bias" in r]
    if a:
        z = np.array([abs(r["acc_bias"]) / r["acc_sigma"] for r in a])
        zt = np.array([abs(r["acc_bias"]) / math.hypot(r["acc_sigma"], r["acc_bound"])
                       for r in a])
        rel = np.array([abs(r["acc_bias"] / r["acc_true"]) for r in a if r["acc_true"]])
        print(f"  acceleration bias at the slip (estimator on the true theta - truth): below "
              f"its 1-sigma noise bar in {100 * np.mean(z < 1):.1f} % of {len(a)} (below noise + "
              f"truncation bound: {100 * np.mean(zt < 1):.1f} %); median |bias|/sigma "
              f"{np.median(z):.2f}, median relative bias {100 * np.median(rel):.2f} %")
    h = [r for r in ok if r.get("theta_a1_rad") is not None]
    if h:
        a1 = np.array([r["theta_a1_rad"] for r in h])
        pr = np.array([r["theta_prior_rad"] for r in h])
        print(f"  first harmonic of theta's error (measured theta - truth): median "
              f"{np.median(a1):.2e} rad, 90th percentile {np.percentile(a1, 90):.2e}; within "
              f"the prior bound used (median {np.median(pr):.2e} rad) in "
              f"{100 * np.mean(a1 <= pr):.1f} % of {len(h)}")
    c = [r for r in rows if "cal_rms_px" in r]
    if c:
        print(f"  calibration ({len(c)}): median |k1 error| "
              f"{np.median([abs(r['cal_k1_err']) for r in c]):.2e}, median |k2 error| "
              f"{np.median([abs(r['cal_k2_err']) for r in c]):.2e}, median centre error "
              f"{np.median([r['cal_centre_err_px'] for r in c]):.2f} px, reprojection RMS "
              f"median {np.median([r['cal_rms_px'] for r in c]):.4f} px, seconds "
              f"{np.mean([r['cal_s'] for r in c]):.2f} (render views + calibrate-camera)")
    print(f"  seconds per recording: render {np.mean([r['render_s'] for r in rows]):.1f}, "
          f"measure (abu measure, in-process, no plots) "
          f"{np.mean([r['measure_s'] for r in rows]):.2f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=200, help="recordings of the random family")
    ap.add_argument("--first", type=int, default=0, help="first seed")
    ap.add_argument("--two-spot", type=int, default=20,
                    help="extra recordings forced to the two-reflection lighting (seeds after "
                         "the family's)")
    ap.add_argument("--alt-two-spot", type=int, default=0,
                    help="extra two-reflection recordings lit by the second highlight model "
                         "(twin.lighting_alt; seeds after the forced two-spot ones)")
    ap.add_argument("--faint-two-spot", type=int, default=0,
                    help="extra two-reflection recordings of the second highlight model with "
                         "the ball faded towards the plane (twin.lighting_alt.faded, factor "
                         f"{FAINT_FACTORS[0]}-{FAINT_FACTORS[1]}; seeds after the others)")
    ap.add_argument("--size", type=int, default=256, help="frame size [px]")
    ap.add_argument("--out", default=None, help="folder for results.jsonl (default: temp)")
    step = ap.add_mutually_exclusive_group()
    step.add_argument("--edge-step", action="store_true",
                      help="track with 'abu measure --edge-step' (the edge-model step also on "
                           "the centre and CD markers of two-reflection recordings)")
    step.add_argument("--no-edge-step", action="store_true",
                      help="track with 'abu measure --no-edge-step' (the contour fits alone)")
    ap.add_argument("--camera", action="store_true",
                    help="per recording: render chessboard views through its optics, "
                         "'abu calibrate-camera', then 'abu measure --camera'")
    ap.add_argument("--views", type=int, default=DEFAULT_VIEWS,
                    help=f"calibration views with --camera (default {DEFAULT_VIEWS})")
    ap.add_argument("--seeds", default=None,
                    help="comma-separated seeds of the family instead of --first/--n")
    ap.add_argument("--keep", default=None,
                    help="folder to keep each recording's tracks and true state in")
    ap.add_argument("--reanalyse", default=None,
                    help="a --keep folder: measure its kept tracks again with the current "
                         "analysis (no rendering) and print the figures")
    ap.add_argument("--lighting-models", choices=["one", "two"], default=None,
                    help="abu measure --lighting-models (default: its default, auto: two "
                         "lighting models for two-reflection recordings)")
    ap.add_argument("--alt-seeds-given", action="store_true",
                    help="start the second highlight model's recordings from the true frame-0 "
                         "positions (--seeds), not the marker finder's")
    ap.add_argument("--summarize", default=None,
                    help="only print the figures of an existing results.jsonl")
    args = ap.parse_args()
    if args.edge_step or args.no_edge_step:
        EXTRA_MEASURE_ARGS.append("--edge-step" if args.edge_step else "--no-edge-step")
    if args.lighting_models:
        ANALYSIS_ARGS.extend(["--lighting-models", args.lighting_models])
    global ALT_SEEDS_GIVEN
    ALT_SEEDS_GIVEN = args.alt_seeds_given
    if args.summarize:
        rows = [json.loads(line) for line in open(args.summarize)]
        print(f"{len(rows)} recordings from {args.summarize}")
        report(rows, "all recordings")
        report([r for r in rows if r["reflections"] == 1], "one reflection (TL ring / stray)")
        report([r for r in rows if r["reflections"] == 2],
               "two reflections (--ball-reflections 2)")
        return
    if args.reanalyse:
        with tempfile.TemporaryDirectory() as tmp:
            rows = reanalyse(Path(args.reanalyse), Path(tmp))
        if args.out:
            Path(args.out).mkdir(parents=True, exist_ok=True)
            with open(Path(args.out) / "results.jsonl", "w") as fh:
                fh.writelines(json.dumps(r) + "\n" for r in rows)
        print(f"{len(rows)} recordings re-analysed from the tracks in {args.reanalyse}; "
              f"abu measure options added: {' '.join(ANALYSIS_ARGS) or 'none (defaults)'}")
        report(rows, "all recordings")
        return
    out = Path(args.out or tempfile.mkdtemp(prefix="bench_coverage_"))
    out.mkdir(parents=True, exist_ok=True)
    log = out / "results.jsonl"
    family = [(s, None) for s in (range(args.first, args.first + args.n) if not args.seeds
                                  else [int(v) for v in args.seeds.split(",")])]
    forced = [(s, "two_spot") for s in range(args.first + args.n,
                                             args.first + args.n + args.two_spot)]
    first_alt = args.first + args.n + args.two_spot
    forced += [(s, "two_spot_alt") for s in range(first_alt, first_alt + args.alt_two_spot)]
    first_faint = first_alt + args.alt_two_spot
    forced += [(s, "two_spot_faint") for s in range(first_faint,
                                                   first_faint + args.faint_two_spot)]
    # interleave the forced two-reflection recordings (one after every few family ones), so
    # that an interrupted run still holds both kinds
    every = max(1, len(family) // max(1, len(forced)))
    jobs = []
    for k, job in enumerate(family):
        jobs.append(job)
        if forced and (k + 1) % every == 0:
            jobs.append(forced.pop(0))
    jobs += forced
    rows = []
    with tempfile.TemporaryDirectory() as tmp, open(log, "a") as fh:
        for k, (seed, lighting) in enumerate(jobs):
            row = one(seed, Path(tmp), args.size, lighting, args.views if args.camera else 0,
                      Path(args.keep) if args.keep else None)
            row["forced_lighting"] = lighting
            rows.append(row)
            fh.write(json.dumps(row) + "\n")
            fh.flush()
            print(f"[{k + 1}/{len(jobs)}] seed {seed} refl {row['reflections']} mu "
                  f"{row['mu']:.5f} -> [{row.get('mu_low')}, {row.get('mu_high')}] "
                  f"{row.get('status', row.get('error'))} ({row['render_s']:.1f} + "
                  f"{row['measure_s']:.1f} s)", flush=True)
    seeds = args.seeds or f"{args.first}..{args.first + args.n - 1}"
    print(f"\nfamily: twin.scenario.random_scenario(seed), seeds {seeds} "
          f"(+{args.two_spot} forced two-spot, +{args.alt_two_spot} "
          f"two-spot of the second highlight model, +{args.faint_two_spot} of it faded), "
          f"{args.size} px, "
          f"3072 frames at 4500 frames/s; confidence {rows[0].get('confidence')}; "
          + (f"camera calibrated on {args.views} chessboard views per recording (--camera)"
             if args.camera else "no camera calibration (family prior on theta's harmonic)")
          + "; abu measure options added: "
          + f"{' '.join(EXTRA_MEASURE_ARGS + ANALYSIS_ARGS) or 'none (defaults)'}")
    report(rows, "all recordings")
    report([r for r in rows if r["reflections"] == 1], "one reflection (TL ring / stray)")
    report([r for r in rows if r["reflections"] == 2], "two reflections (--ball-reflections 2)")
    report([r for r in rows if r["reflections"] == 2 and r.get("forced_lighting")
            not in ("two_spot_alt", "two_spot_faint")],
           "two reflections, first highlight model (twin.lighting)")
    report([r for r in rows if r.get("forced_lighting") == "two_spot_alt"],
           "two reflections, second highlight model (twin.lighting_alt)")
    report([r for r in rows if r.get("forced_lighting") == "two_spot_faint"],
           "two reflections, second highlight model, faint ball (twin.lighting_alt.faded)")
    print(f"\nper-recording rows: {log}")


if __name__ == "__main__":
    main()
