"""Designed prescribed-profile runs (report ch. 6's drive), rendered by the twin and measured.

For each prior range (a factor of 2 wide) ``abu design`` chooses the profile for a tracking
drive (bandwidth 150 rad/s with a stated 95 % interval of +-10 %, torque lag 5 ms;
:mod:`harness.planning.design_profile`). Each run draws from its seed: the true mu uniform in
the range, mu_d / mu in [0.6, 1], the true bandwidth within +-5 % of the stated one, and the
harsh twin's camera (lamps, lens, sensor, set-up: :func:`twin.scenario.random_scenario`,
ring lighting). The recording is rendered (:mod:`twin.tracking_scenario`), tracked (``abu
track``) and analysed three ways:

* ``profile model``: ``abu measure --kinematics drive-model --profile`` (the default fit);
* ``profile model, exact loop``: the same with the true bandwidth as the stated value and a
  tight interval (what a perfectly identified drive gives);
* ``exact kinematics``: omega, omega_dot replaced by the plant's (an oracle), with the
  default lens prior on theta's harmonic; ``exact, no lens prior``: without it, the width the
  beta data allow.

Printed per analysis: coverage (both bounds finite and holding mu), misses by more than 2 %
of mu, median and 90th percentile relative width; and the design's predicted width beside the
measured one (median ratio). Run::

    nice python benchmarks/bench_profile_drive.py --n 24 --first 0
"""
from __future__ import annotations

import argparse
import io
import os
import sys
import tempfile
import time
from contextlib import redirect_stderr, redirect_stdout
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from abu.cli.main import main as abu_main  # noqa: E402
from controller.drive import Drive  # noqa: E402
from harness.planning.design_profile import ProfileDesignSpec, design_profile  # noqa: E402
from measurement.imaging.tracks_io import read_tracks_csv  # noqa: E402
from measurement.inference import analysis  # noqa: E402
from measurement.inference.analysis import AnalysisOptions, analyse_tracks  # noqa: E402
from measurement.inference.infer_mu import InferenceOptions  # noqa: E402
from measurement.kinematics.profile_model import ProfileModelInput  # noqa: E402
from twin.scenario import render_scenario_frames, simulate_scenario  # noqa: E402
from twin.tracking_scenario import tracking_scenario, tracking_spec  # noqa: E402

RANGES = ((0.01, 0.02), (0.02, 0.04), (0.03, 0.06))
BANDWIDTH, TAU = 150.0, 0.005
DRIVE = Drive(model="tracking", bandwidth=BANDWIDTH, tau_motor=TAU,
              ci95={"bandwidth_rad_s": (0.9 * BANDWIDTH, 1.1 * BANDWIDTH)})
MEASURED = analysis._kinematics


def _exact(state: dict):
    def kinematics(time_, theta, opt):
        k = MEASURED(time_, theta, opt)
        return replace(k, omega=state["omega"], omega_dot=state["alpha"],
                       sigma_omega=k.sigma_omega * 1e-6, sigma_omega_dot=k.sigma_omega_dot * 1e-6,
                       bias_omega_dot=np.zeros_like(k.omega_dot))
    return kinematics


def _render_and_track(seed: int, design, mu: float, mu_d: float, wb: float):
    """(tracks, true state, scenario) of one run, or (None, None, scenario) when untracked."""
    spec = tracking_spec(DRIVE, design.profile, bandwidth=wb)
    scn = tracking_scenario(seed, spec, mu, mu_d, lighting="ring")
    state, pos = simulate_scenario(scn)
    frames = render_scenario_frames(scn, state, pos)
    with tempfile.TemporaryDirectory() as tmp:
        rec = Path(tmp) / "rec.npy"
        np.save(rec, frames)
        with redirect_stdout(io.StringIO()), redirect_stderr(io.StringIO()):
            status = abu_main(["track", str(rec), "--out", str(Path(tmp) / "t"), "--quiet",
                               "--fps", repr(scn.fps)])
        if status != 0:
            return None, state, scn
        return read_tracks_csv(Path(tmp) / "t" / "tracks.csv"), state, scn


def one(seed: int, design, cache: Path | None = None, mu_d_ratio: float | None = None) -> dict:
    """Render, track and measure one designed run (tracks reused from ``cache`` if there)."""
    rng = np.random.default_rng([seed, 18])
    lo, hi = design.spec.mu_lo, design.spec.mu_hi
    mu = float(rng.uniform(lo, hi))
    mu_d = mu * float(rng.uniform(0.6, 1.0))
    if mu_d_ratio is not None:
        mu_d = mu * mu_d_ratio
    wb = BANDWIDTH * float(rng.uniform(0.95, 1.05))
    key = None if cache is None else cache / (
        f"s{seed}_{lo:g}_{hi:g}_{design.spec.sweep}_{design.spec.speed_max:.4g}"
        f"_{design.rate:.6g}{'' if mu_d_ratio is None else f'_mud{mu_d_ratio:g}'}.npz")
    if key is not None and key.exists():
        z = np.load(key)
        tracks = SimpleNamespace(time=z["time"], x=z["x"], y=z["y"], lost=z["lost"])
        state = {"omega": z["omega"], "alpha": z["alpha"]}
        l_m, d_m = float(z["l"]), float(z["d"])
    else:
        tracks, state, scn = _render_and_track(seed, design, mu, mu_d, wb)
        if tracks is None:
            return {"seed": seed, "mu": mu, "error": 1}
        l_m, d_m = scn.ball.l, scn.ball.d
        if key is not None:
            np.savez(key, time=tracks.time, x=tracks.x, y=tracks.y, lost=tracks.lost,
                     omega=state["omega"], alpha=state["alpha"], l=l_m, d=d_m)
    exact_drive = Drive(model="tracking", bandwidth=wb, tau_motor=TAU,
                        ci95={"bandwidth_rad_s": (wb * 0.999, wb * 1.001)})
    row = {"seed": seed, "mu": mu, "mu_d_over_mu": mu_d / mu, "bounds": {},
           "predicted": float(np.interp(mu, design.mus, design.width)),
           "predicted_upper": float(np.interp(mu, design.mus, design.upper())),
           "speed_rad_s": float(np.interp(mu, design.mus, design.speed)),
           "sweep_rate_per_s": design.rate}
    for name, opt, exact in (
            ("profile model", AnalysisOptions(kinematics="drive-model", drive_model=ProfileModelInput(
                DRIVE, design.profile)), False),
            ("profile model, exact loop", AnalysisOptions(
                kinematics="drive-model", drive_model=ProfileModelInput(exact_drive,
                                                                        design.profile)), False),
            ("exact kinematics", AnalysisOptions(), True),
            ("exact, no lens prior", AnalysisOptions(
                inference=InferenceOptions(theta_harmonic_rad=0.0)), True)):
        analysis._kinematics = _exact(state) if exact else MEASURED
        try:
            _, s = analyse_tracks(tracks.time, tracks.x, tracks.y, l=l_m, d=d_m,
                                  lost=tracks.lost, options=opt)
        finally:
            analysis._kinematics = MEASURED
        row["bounds"][name] = (s["mu_low"], s["mu_high"], s["estimator"].get("model"))
        if s["estimator"].get("model") == "refused":
            row.setdefault("why", {})[name] = s["estimator"].get("why", "")
    return row


def report(rows: list[dict]) -> None:
    ok = [r for r in rows if "error" not in r]
    print(f"{len(rows)} runs, {len(rows) - len(ok)} not tracked")
    for name in ok[0]["bounds"]:
        hit, miss2, widths, finite, refused = 0, [], [], 0, 0
        for r in ok:
            lo, hi, model = r["bounds"][name]
            refused += model == "refused"
            if lo is None or hi is None:
                continue
            finite += 1
            mu = r["mu"]
            hit += lo <= mu <= hi
            widths.append((hi - lo) / (0.5 * (lo + hi)))
            miss = max(lo - mu, mu - hi, 0.0) / mu
            if miss > 0.02:
                miss2.append((r["seed"], round(100 * miss, 1)))
        w = np.array(widths)
        print(f"  {name:28s} coverage {100 * hit / len(ok):5.1f} % ({hit}/{len(ok)}, finite "
              f"{finite}), misses > 2 %: {len(miss2)} {miss2[:5]}, width median "
              f"{100 * np.median(w):.1f} %, 90th {100 * np.percentile(w, 90):.1f} %"
              + (f", model refused {refused}" if refused else ""))
    whys = [(r["seed"], w[:70]) for r in ok for w in r.get("why", {}).values()]
    if whys:
        print(f"  refusals: {whys[:6]}")
    meas = np.array([(r["bounds"]["profile model"][1] - r["bounds"]["profile model"][0])
                     / r["mu"] if r["bounds"]["profile model"][0] is not None
                     and r["bounds"]["profile model"][1] is not None else np.nan for r in ok])
    pred = np.array([r["predicted"] for r in ok])
    ratio = meas / pred
    inside = np.mean((ratio >= 0.77) & (ratio <= 1.3))
    upper = np.array([r["predicted_upper"] for r in ok])
    print(f"  measured / predicted width (profile model): median {np.nanmedian(ratio):.2f}, "
          f"10-90 % {np.nanpercentile(ratio, 10):.2f}-{np.nanpercentile(ratio, 90):.2f}, within "
          f"[0.77, 1.3] {100 * inside:.0f} %; measured <= the upper prediction (mu_d = mu) "
          f"{int(np.sum(meas <= upper))} of {len(ok)}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=24, help="runs (spread over the ranges)")
    ap.add_argument("--first", type=int, default=0, help="first seed")
    ap.add_argument("--speed-max-hz", type=float, default=40.0)
    ap.add_argument("--sweep", choices=["decelerate", "accelerate"], default="decelerate")
    ap.add_argument("--cache", default=None, help="keep the tracks here and reuse them")
    ap.add_argument("--rows", default=None, help="also write the rows as JSON here")
    ap.add_argument("--mu-d-ratio", type=float, default=None,
                    help="mu_d / mu of every run (default: drawn in [0.6, 1])")
    a = ap.parse_args()
    designs = []
    for lo, hi in RANGES:
        d = design_profile(ProfileDesignSpec(lo, hi, DRIVE, speed_max=a.speed_max_hz * 2 * np.pi,
                                             sweep=a.sweep))
        designs.append(d)
        print(f"design [{lo:g}, {hi:g}]: sweep rate {d.rate:.4g} /s, speed "
              f"{d.phases['speed_start_rad_s'] / 2 / np.pi:.3g} -> "
              f"{d.phases['speed_end_rad_s'] / 2 / np.pi:.3g} Hz, predicted width median "
              f"{100 * np.median(d.width):.1f} %, worst {100 * d.width.max():.1f} %")
    rows = []
    c0 = time.process_time()
    for k in range(a.n):
        seed = a.first + k
        cache = None if a.cache is None else Path(a.cache)
        if cache is not None:
            cache.mkdir(parents=True, exist_ok=True)
        rows.append(one(seed, designs[k % len(designs)], cache, a.mu_d_ratio))
        r = rows[-1]
        print(f"  seed {seed}: mu {r['mu']:.4g} " + " | ".join(
            f"{lo if lo is None else round(lo, 5)}..{hi if hi is None else round(hi, 5)} {m}"
            for lo, hi, m in r.get("bounds", {}).values()), flush=True)
    ratio = "in [0.6, 1]" if a.mu_d_ratio is None else f"{a.mu_d_ratio:g}"
    print(f"prescribed-profile drive, seeds {a.first}..{a.first + a.n - 1}, ranges "
          f"{', '.join(f'[{lo:g}, {hi:g}]' for lo, hi in RANGES)}, sweep {a.sweep}, speed cap "
          f"{a.speed_max_hz:g} Hz, mu_d / mu {ratio} (CPU {time.process_time() - c0:.0f} s; "
          "shared machine)")
    report(rows)
    if a.rows:
        import json
        Path(a.rows).write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
