"""The model-based confidence set on mu (measurement.inference.infer_mu): coverage on many seeded
recordings of the harsh twin's family, null bounds with a status, the slip integration against
the exact plant.

Coverage here (a smaller version of ``benchmarks/bench_coverage.py``, which renders and tracks
raw frames): the harsh twin's random drives (``twin.scenario.random_scenario``: PI
staircases with setpoint weighting / filters, smooth acceleration profiles, torque lags 0-30 ms,
mu in [0.005, 0.06], mu_d / mu in [0.6, 1]) are simulated on the exact plant and its camera
geometry (lens distortion, eccentric centre marker); the marker tracks get white tracking
noise and a lighting disturbance of the ball's apparent centre with harmonics 1-3 of the ball's
angle (the cause of the report's harmonic, sec. 5.2), of the size measured on the rendered
twin. Rendering 30 recordings would cost
minutes; the image chain is covered by the benchmark and by tests/test_end_to_end_twin.py.
"""
from __future__ import annotations

import math
import os

import numpy as np
import pytest

from abu_model.params import BallParams, PlantParams
from abu_model.plant import AbuPlant
from measurement.inference.analysis import analyse_tracks
from measurement.inference.slip_model import signed_mu_req, slip_displacement

from synthetic_tracks import measured_pixels, simulate

N_COVERAGE = 30
TWO_PI = 2.0 * math.pi


def scenario_tracks(seed: int, n_frames: int = 2400, light_scale: float = 1.0,
                    lead_s: float = 0.0):
    """(times, x, y, ball, truth) of one drawn scenario at the tracks level (``light_scale``
    multiplies the lighting shift of the ball's apparent centre). ``lead_s`` [s]: the drive's
    constant starting speed held that much longer before the scenario (the ball stuck): a
    late slip in a long record (``twin.scenario.with_lead``; ParameterError for a drive that
    starts accelerating)."""
    from twin.scenario import random_scenario, simulate_scenario, with_lead
    scn = random_scenario(seed, n_frames=n_frames)
    state, pos = simulate_scenario(scn)
    if lead_s:
        scn, state, pos = with_lead(scn, state, lead_s)
    rng = np.random.default_rng([seed, 7])
    phi = state["theta"] + state["beta"]
    shift = np.zeros((phi.size, 2))
    for k in (1, 2, 3):     # apparent-centre shift of the lit ball, fixed lamps: f(phi)
        # amplitudes of the size measured on the rendered twin (~0.1 px, 0.003 rad on beta)
        a, p = light_scale * rng.uniform(0.02, 0.12) / k, rng.uniform(0, TWO_PI, 2)
        shift[:, 0] += a * np.cos(k * phi + p[0])
        shift[:, 1] += a * np.sin(k * phi + p[1])
    pts = [pos["centre"], pos["cd"], pos["ball"] + shift]
    sigma = rng.uniform(0.008, 0.02)
    x = np.stack([p[:, 0] for p in pts], axis=1) + sigma * rng.standard_normal((phi.size, 3))
    y = np.stack([p[:, 1] for p in pts], axis=1) + sigma * rng.standard_normal((phi.size, 3))
    return scn.times, x, y, scn.ball, state


#: Seeds of the coverage test: a slice nothing was tuned on (the options were chosen on seeds
#: 0-299 of the family; SLOW_ONSET_SEEDS below are picked from those).
COVERAGE_SEEDS = range(4000, 4000 + N_COVERAGE)
#: Ceiling of the median relative width at the tracks level (measured 25.7 % on these seeds;
#: the rendered family's figure in the README is 34.9 %, wider through tracking and lighting).
WIDTH_CEILING = 0.30
#: Least share of informative results (both bounds finite).
MIN_INFORMATIVE = 0.9


def coverage_rows(seeds) -> list[dict]:
    """One row per seed: the stated interval, whether it holds mu (both bounds needed: a null
    bound is no hit), its miss and width."""
    rows = []
    for seed in seeds:
        times, x, y, ball, state = scenario_tracks(seed)
        _, s = analyse_tracks(times, x, y, l=ball.l, d=ball.d)
        mu = ball.mu
        lo, hi = s["mu_low"], s["mu_high"]
        both = lo is not None and hi is not None
        inside = both and lo <= mu <= hi
        miss = max((lo - mu) / mu if lo is not None else 0.0,
                   (mu - hi) / mu if hi is not None else 0.0, 0.0)
        t_true = float(state["switches"][0]) if len(state["switches"]) else None
        rows.append({"seed": seed, "mu": mu, "lo": lo, "hi": hi, "both": both,
                     "inside": inside, "miss": miss, "status": s["status"],
                     "width": s["relative_width"], "t_true": t_true,
                     "t_lo": s["t_slip_low"], "t_hi": s["t_slip_high"]})
        # a null bound is never reported as "ok"; both bounds are "ok" unless the model's set
        # and the running max disagree ("check: ...", analysis_summary._disagreement)
        assert both == (s["status"] == "ok" or s["status"].startswith("check: ")), s["status"]
    return rows


def test_coverage_of_the_stated_interval_on_the_harsh_family():
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    rows = coverage_rows(COVERAGE_SEEDS)
    informative = float(np.mean([r["both"] for r in rows]))
    coverage = float(np.mean([r["inside"] for r in rows]))
    widths = [r["width"] for r in rows if r["width"] is not None]
    big = [r for r in rows if r["miss"] > 0.02]
    onset = [r for r in rows if r["t_true"] is not None and r["t_lo"] is not None
             and r["t_hi"] is not None]
    onset_cov = float(np.mean([r["t_lo"] <= r["t_true"] <= r["t_hi"] for r in onset]))
    print(f"\nharsh-twin drives at the tracks level, {N_COVERAGE} recordings "
          f"(twin.scenario seeds {COVERAGE_SEEDS[0]}..{COVERAGE_SEEDS[-1]}, 2400 frames): "
          f"both bounds in {informative:.0%}, coverage of the stated 95 % interval "
          f"{coverage:.0%} (null bounds count as misses), missing mu by > 2 %: {len(big)}, "
          f"median relative width {np.median(widths):.1%}, 90th percentile "
          f"{np.percentile(widths, 90):.1%}; onset bracket holds the true onset in "
          f"{onset_cov:.0%} of {len(onset)}")
    assert informative >= MIN_INFORMATIVE, [r for r in rows if not r["both"]]
    assert coverage >= 0.90, [r for r in rows if not r["inside"]]
    # issue 7: no interval misses mu by more than 2 %
    assert not big, big
    assert np.median(widths) < WIDTH_CEILING, np.median(widths)
    assert len(onset) >= 0.6 * len(rows) and onset_cov >= 0.95, onset


def test_never_slipping_record_has_a_null_upper_bound():
    rec = simulate(0.03, "steps", n=1500)            # max mu_req ~0.023: the ball never slips
    assert math.isinf(rec.t_slip)
    x, y = measured_pixels(rec, sigma_px=0.03, harmonic_px=0.4, seed=2)
    _, s = analyse_tracks(rec.time, x, y, l=rec.l, d=rec.d)
    assert s["mu_high"] is None and s["status"] != "ok"
    assert s["status"].startswith("no slip")
    assert s["mu_low"] is not None and s["mu_low"] <= rec.mu
    assert s["mu_d"] is None and s["mu_d_low"] is None


def test_record_slipping_before_the_trusted_region_has_a_null_lower_bound():
    rec = simulate(0.003, "steps", n=1500)           # slips at the first step, 10 ms, before
    assert rec.t_slip < 0.018                        # the trusted region starts (21 ms)
    x, y = measured_pixels(rec, sigma_px=0.03, harmonic_px=0.4, seed=3)
    _, s = analyse_tracks(rec.time, x, y, l=rec.l, d=rec.d)
    assert s["estimator"]["trusted_start_s"] > rec.t_slip
    assert s["mu_low"] is None and s["status"] != "ok"
    assert "before" in s["status"] or "start" in s["status"]


def test_lost_markers_across_the_slip_null_both_bounds():
    rec = simulate(0.012, "ramp", n=1500)
    x, y = measured_pixels(rec, sigma_px=0.03, seed=5)
    lost = np.zeros((rec.time.size, 3), dtype=bool)
    i = int(rec.t_slip * 4500)
    lost[i - 2: i + 2, 2] = True                     # the ball lost for 4 frames at the slip
    _, s = analyse_tracks(rec.time, x, y, l=rec.l, d=rec.d, lost=lost)
    assert s["mu_low"] is None and s["mu_high"] is None
    assert "lost" in s["status"]
    lost_far = np.zeros_like(lost)
    lost_far[100:103, 2] = True                      # far from the slip: no effect
    _, s2 = analyse_tracks(rec.time, x, y, l=rec.l, d=rec.d, lost=lost_far)
    assert s2["status"] == "ok" and s2["mu_low"] <= rec.mu <= s2["mu_high"]


@pytest.mark.parametrize("mu_d_ratio", [1.0, 0.7])
def test_slip_integration_matches_the_exact_plant(mu_d_ratio):
    """The vectorised (cumulative-sum) slip model against abu_model.plant.AbuPlant, an
    independent event-located integrator, on a linear acceleration ramp (report sec. 4.1)."""
    mu = 0.008
    ball = BallParams(mu=mu, mu_d=mu * mu_d_ratio)
    plant = AbuPlant(PlantParams(ball=ball, J_abu=4.5e-5), omega0=-2 * math.pi * 9)
    fps, n = 4500.0, 1500
    t = np.arange(n) / fps
    omega, alpha, beta = np.empty(n), np.empty(n), np.empty(n)
    for k in range(n):
        st = plant.state
        omega[k], beta[k] = st.omega, st.beta
        alpha[k] = -300.0 * t[k]
        if k < n - 1:
            plant.advance(1.0 / fps, 4.5e-5 * alpha[k], 4.5e-5 * -300.0)
    q = signed_mu_req(omega, alpha, ball.l, ball.d, +1)
    disp, onset = slip_displacement(t, q, omega, np.array([mu]), np.array([ball.mu_dynamic]),
                                    +1, ball.d / ball.l)
    true = beta - beta[0]
    assert true[-1] > 0.01                           # the ball slipped well within the record
    t_true = t[np.flatnonzero(true > 0)[0] - 1]
    assert abs(onset[0] - t_true) < 2.0 / fps
    # the linearised model reproduces the plant's displacement within 2 %
    np.testing.assert_allclose(disp[0, -1], true[-1], rtol=0.02)
    big = true > 0.1 * true[-1]
    np.testing.assert_allclose(disp[0][big], true[big], rtol=0.03)


# Slow continuous onsets (issue 7): staircases through a long torque lag (>= 12 ms), mu_d / mu
# >= 0.9 (beta leaves rest as dt^3), the stick stretch of the trusted region covering less than
# one turn, so the slip enters ball angles whose lighting harmonic the stick never showed
# (seeds of twin.scenario picked by those criteria from 0..299). Before the in-window
# harmonic refit (InferenceOptions.harmonic_orders = () then) seed 141 put its lower bound
# 4.8 % above mu; rendered, seeds 58 and 141 of bench_coverage missed by 6.2 % and 2.5 %.
SLOW_ONSET_SEEDS = (5, 8, 58, 118, 141, 191, 198, 286)


def test_slow_onsets_lower_bound_stays_below_mu():
    rows = []
    for seed in SLOW_ONSET_SEEDS:
        times, x, y, ball, state = scenario_tracks(seed)
        _, s = analyse_tracks(times, x, y, l=ball.l, d=ball.d)
        rows.append((seed, s["mu_low"], ball.mu, s["status"]))
    print(f"\nslow onsets (staircase, lag >= 12 ms, mu_d/mu >= 0.9, < 1 turn of stick), seeds "
          f"{SLOW_ONSET_SEEDS}: mu_low / mu - 1 = "
          f"{[None if lo is None else round(100 * (lo / mu - 1), 1) for _, lo, mu, _ in rows]} %")
    assert all(st == "ok" for *_, st in rows), rows
    assert all(lo <= mu for _, lo, mu, _ in rows), rows


def test_lower_bound_takes_the_sup_quantile_and_the_upper_the_pointwise_z():
    """_bounds_and_status on a flat profile [a, b]: the lower bound is widened by the Rice sup
    quantile z_lo (the largest error over the stretch that set it), the upper by the pointwise
    z; the bias bounds add linearly (closed forms of scale_nuisance_bounds)."""
    from measurement.inference.infer_mu import _bounds_and_status, _ProfileSet
    from measurement.inference.kinematic_nuisance import KinematicNuisance
    from measurement.inference.types import InferenceOptions

    z = 1.959963984540054
    grid = np.linspace(0.02, 0.03, 11)
    pset = _ProfileSet(grid, np.zeros(11), 5, 1.0, np.zeros(11), np.arange(11))
    nuis = KinematicNuisance(rel_noise=0.01, rel_bias=0.002, rel_noise_lo=0.02,
                             rel_bias_lo=0.003, z_lo=3.1, reach_s=0.05)
    lo, hi, status = _bounds_and_status(pset, nuis, False, False, z * z, InferenceOptions())
    assert status == "ok"
    assert lo == pytest.approx(0.02 * (1 - 3.1 * 0.02 - 0.003), rel=1e-12)
    assert hi == pytest.approx(0.03 * (1 + z * 0.01 + 0.002), rel=1e-12)


def test_rice_quantile_of_the_savgol_error_maximum_against_monte_carlo():
    """The lower bound's noise quantile (measurement.inference.sup_noise, Rice's formula) against the
    simulated maximum of white noise through the default omega_dot kernel (Savitzky-Golay
    42 ms, degree 9, 4500 frames/s): exceeded at most at the stated rate (one-sided 2.5 %), and
    not grossly more conservative (above 1 %)."""
    from scipy.signal import fftconvolve

    from measurement.inference import sup_noise
    from measurement.kinematics.estimators import _odd_window, stable_savgol_coeffs

    dt = 1.0 / 4500.0
    c2 = stable_savgol_coeffs(_odd_window(0.042, dt, 11), 9, 2, dt)
    rho = np.correlate(c2, c2, "full")[c2.size - 1:] / float(c2 @ c2)
    lam2 = sup_noise.second_spectral_moment(float(rho[1]), dt)
    x = fftconvolve(np.random.default_rng(5).standard_normal(3_000_000), c2, "valid")
    x /= np.linalg.norm(c2)
    for duration in (0.0, 0.01, 0.05, 0.15):
        u = sup_noise.sup_quantile(0.025, duration, lam2)
        m = max(1, int(round(duration / dt)))
        windows = x[: x.size // m * m].reshape(-1, m).max(axis=1)
        rate = float(np.mean(windows > u))
        print(f"max over {1e3 * duration:.0f} ms: u = {u:.3f}, exceeded in {rate:.4f}")
        assert 0.010 < rate <= 0.027, (duration, u, rate)


def test_rice_quantile_bisection_equals_a_library_root_finder():
    """sup_noise solves Rice's bound by bisection (scipy.optimize cost `abu measure` 0.33 s of
    imports): the same root as SciPy's brentq over levels, durations and spectral moments, and
    the bound at the root equals the level."""
    from statistics import NormalDist

    from scipy.optimize import brentq

    from measurement.inference import sup_noise
    for alpha in (0.005, 0.025, 0.05):
        z0 = NormalDist().inv_cdf(1.0 - alpha)
        for duration in (1e-3, 0.01, 0.1, 1.0):
            for lam2 in (1e3, 1.2e6, 1e8):
                u = sup_noise.sup_quantile(alpha, duration, lam2)
                ref = brentq(lambda v: sup_noise.sup_exceedance(v, duration, lam2) - alpha,
                             z0, 40.0, xtol=1e-14)
                assert abs(u - ref) < 1e-12, (alpha, duration, lam2, u, ref)
                assert u > z0
                assert abs(sup_noise.sup_exceedance(u, duration, lam2) - alpha) < 1e-12 * alpha \
                    + 1e-15


def test_lower_bound_of_a_ball_stuck_on_a_plateau_of_mu_req():
    """A ball that never slips while mu_req stays at q0 for the whole record (omega' = -k
    omega^2: the worst case for the noise, every frame's error can set the bound): mu_low must
    stay at or below q0 (the largest mu_req the data prove the ball survived) in >= 90 % of
    noise seeds at 95 % (one-sided 97.5 %). The largest measured q alone lies above q0 in
    almost every seed. A (wrong) upper bound comes at about the test's level."""
    from synthetic_tracks import Record

    l, d, q0, fps, n = 1.15e-2, 3.0e-3, 0.02, 4500.0, 2000
    k = q0 * l / (l - d / 5.0)
    t = np.arange(n) / fps
    w0 = -2 * math.pi * 9
    omega = w0 / (1.0 + k * w0 * t)
    rec = Record(t, -np.log(1.0 + k * w0 * t) / k, omega, -k * omega ** 2, np.full(n, 0.4),
                 np.zeros(n, int), 0.03, math.inf, l, d)
    above, raw_above, bounded, spurious = 0, 0, 0, 0
    for seed in range(20):
        x, y = measured_pixels(rec, sigma_px=0.03, seed=100 + seed)
        table, s = analyse_tracks(rec.time, x, y, l=l, d=d)
        spurious += s["mu_high"] is not None and s["mu_high"] < rec.mu
        # null (with a status) where the data also fit a ball sliding from the start: q at
        # the start of the plateau is q0 too
        if s["mu_low"] is not None:
            bounded += 1
            above += s["mu_low"] > q0
        trusted = np.asarray(table["trusted"], bool)
        raw_above += float(np.max(np.asarray(table["mu_req"])[trusted])) > q0
    print(f"\nplateau q0 = {q0}: mu_low above q0 in {above} of {bounded} seeds with a lower "
          f"bound (of 20); the largest measured mu_req above q0 in {raw_above} of 20; an upper "
          f"bound below mu = {rec.mu} (the ball never slipped) in {spurious} of 20")
    assert raw_above >= 15 and bounded >= 10
    assert above <= max(1, round(0.1 * bounded))
    # the "never slips" test rejects at its level: about 1 in 20 (4 or more: p < 2 %)
    assert spurious <= 3


def test_scale_nuisance_bounds_against_closed_forms():
    """Profiling the relative scale error e of q (1-sigma s_e) out of the deviance: a flat
    profile on [a, b] gets the full z s_e on each side; a quadratic profile of half-width h
    about m0 gets (to first order in h/m0, s_e) the quadrature sum z sqrt(h^2 + (s_e m0)^2);
    without the nuisance the bounds are the profile's own; a larger budget on one side (the
    sup quantile of the lower bound) reaches further on that side only."""
    from measurement.inference.infer_mu import scale_nuisance_bounds

    z = 1.959963984540054
    crit = z * z
    mu = np.geomspace(0.01, 0.05, 40001)
    flat = np.where((mu >= 0.02) & (mu <= 0.03), 0.0, 99.0)
    keep = flat <= crit
    lo, hi = scale_nuisance_bounds(mu[keep], flat[keep], (crit, crit), (0.04, 0.04))
    assert lo == pytest.approx(0.02 * (1 - z * 0.04), rel=1e-4)
    assert hi == pytest.approx(0.03 * (1 + z * 0.04), rel=1e-4)
    lo3, hi3 = scale_nuisance_bounds(mu[keep], flat[keep], (9.0, crit), (0.04, 0.04))
    assert lo3 == pytest.approx(0.02 * (1 - 3 * 0.04), rel=1e-4) and hi3 == hi
    # bias bounds add linearly; relative errors past 100 % leave the trivial lower bound 0
    # (tracks seed 38: q's noise at a slip where omega_dot ~ 0 is 540 % of q)
    lo_b, hi_b = scale_nuisance_bounds(mu[keep], flat[keep], (crit, crit), (0.04, 0.04),
                                       (0.02, 0.03))
    assert lo_b == pytest.approx(0.02 * (1 - z * 0.04 - 0.02), rel=1e-4)
    assert hi_b == pytest.approx(0.03 * (1 + z * 0.04 + 0.03), rel=1e-4)
    assert scale_nuisance_bounds(mu[keep], flat[keep], (crit, crit), (5.4, 0.04),
                                 (2.7, 0.0))[0] == 0.0
    m0, s_e = 0.03, 0.005
    for h_rel in (0.002, 0.005, 0.02):          # profile 1-sigma half-width / m0
        stat = ((mu - m0) / (h_rel * m0)) ** 2
        keep = stat <= crit
        lo, hi = scale_nuisance_bounds(mu[keep], stat[keep], (crit, crit), (s_e, s_e))
        half = z * m0 * math.hypot(h_rel, s_e)
        assert (hi - m0) == pytest.approx(half, rel=0.02)
        assert (m0 - lo) == pytest.approx(half, rel=0.02)
        lo0, hi0 = scale_nuisance_bounds(mu[keep], stat[keep], (crit, crit), (0.0, 0.0))
        assert (hi0 - m0) == pytest.approx(z * h_rel * m0, abs=2e-6)   # the grid step
        assert lo < lo0 and hi > hi0
