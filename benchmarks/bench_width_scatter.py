"""How random is one recording's width? The floor under any predictor of designed runs' widths.

``bench_designed_runs.py`` asks the width model for measured / predicted width within [0.77,
1.3] in >= 90 % of designed runs. A single recording's width is itself random: even a perfect
predictor of the *expected* width cannot beat the scatter of widths at fixed everything. This
benchmark measures that scatter and splits the designed runs' ratio into it and the
predictor's own error.

1. **Population**: the designed runs of ``bench_designed_runs.py`` (seeds ``--first`` ..,
   default 1000-1071: range and drive by seed, true mu, mu_d, lighting, lens as there), rendered
   and measured here (or read from its ``--rows`` file with ``--population-rows``).
2. **Cases** (``--cases``, default two per drive, five of them outside the band in the
   population): each is re-rendered ``--repeats`` times (the population's recording is
   repeat 0) with the same design, true mu, mu_d, lighting, lens and sensor, changing only
   * ``noise``: the camera noise realisation (the twin draws the sensor's noise, its column
     pattern included, from ``default_rng([Scenario.seed, 1])``: a new noise seed
     10^6 k + seed; the scenario itself is drawn from the case's seed as before);
   * ``phase``: where the run happens relative to the lamps and lens: the ABU's start angle
     theta(0) uniform in [0, 2 pi) (the whole motion turned, same noise);
   * ``both``: both at once (what two recordings of the same planned run differ by);
   * ``mu_d``: both, and mu_d / mu redrawn uniformly in [0.6, 1] as the population draws it
     (what a plan faces: it knows the design, mu, the camera and the lighting, never mu_d).
   Each is measured with ``abu measure`` and the benchmark's options.
3. Printed: per case and pooled, the sd and 5-95 % range of ln(width / case geometric mean);
   the share of recordings within [0.77, 1.3] of their case's geometric mean and of its median
   (the best any predictor of the expected or median width can do), with a bootstrap over
   cases; for the population, measured / predicted (the width model's expected) split into
   within-case scatter and between-case error, and how much of the latter each planned or
   drawn covariate explains (mu_d / mu, the stick stretch in ABU turns before the planned slip,
   the drive's torque lag, reflections, exposure, the speed at the slip).

Run (one core: 16 min CPU for the defaults, 360 recordings rendered and measured)::

    OPENBLAS_NUM_THREADS=1 nice python benchmarks/bench_width_scatter.py
    python benchmarks/bench_width_scatter.py --cases 1026 1005 --repeats 4 --modes both
    python benchmarks/bench_width_scatter.py --population-rows designed.jsonl \
        --cases $(seq 1048 1059) --modes both mu_d   # one whole cycle of the 12 designs: cases
                                                     # not chosen by their outcome

Seeds: the population and cases are seeds of ``bench_designed_runs.py``'s validation slice
(1000-1071); the repeats' noise seeds and start angles are drawn from
``default_rng([case seed, 11, 13 or 14, k])`` and 10^6 k + seed: same arguments, same figures.
"""
from __future__ import annotations

import argparse
import io
import json
import math
import os
import sys
import tempfile
import time
from contextlib import redirect_stderr, redirect_stdout
from dataclasses import replace
from multiprocessing import Pool
from pathlib import Path

from bench_args import positive_int  # the scripts' folder is on sys.path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np  # noqa: E402

import bench_designed_runs as designed  # noqa: E402
from abu.cli.main import main as abu_main  # noqa: E402
from twin.scenario import marker_positions, random_scenario, render_scenario_frames, \
    simulate_scenario  # noqa: E402

TWO_PI = 2.0 * math.pi
LOG_BAND = (math.log(designed.RATIO_BAND[0]), math.log(designed.RATIO_BAND[1]))
#: two per drive (config of seed s: (s - 1000) mod 12), ranges covered; in the final
#: default's population 1026, 1005, 1064, 1032, 1022 fell outside [0.77, 1.3]
DEFAULT_CASES = (1026, 1037, 1005, 1064, 1032, 1018, 1022, 1021)
MODES = ("noise", "phase", "both", "mu_d")
#: the design's fields a row keeps (as ``bench_designed_runs``'s rows)
DESIGN_KEYS = ("omega0_hz", "omega_end_hz", "t0_s", "te_s", "rounding", "step_hz", "fps_hz",
               "frames", "record_s")


def config_of(seed: int, first: int) -> tuple[tuple[float, float], str]:
    """(prior range, drive name) of a designed run's seed, as ``bench_designed_runs``."""
    cfg = designed.configs()
    return cfg[(seed - first) % len(cfg)]


def variant(mode: str, seed: int, k: int) -> tuple[int, float, float | None]:
    """(noise seed, start angle [rad], mu_d / mu or None: the case's) of repeat k of a case
    (k = 0: the original run)."""
    if k == 0:
        return seed, 0.0, None
    rng = np.random.default_rng([seed, {"noise": 10, "phase": 11, "both": 13, "mu_d": 14}[mode],
                                 k])
    noise_seed = seed + 10 ** 6 * k if mode != "phase" else seed
    angle_rad = float(rng.uniform(0.0, TWO_PI)) if mode != "noise" else 0.0
    rho = float(rng.uniform(*designed.MU_D_RATIO)) if mode == "mu_d" else None
    return noise_seed, angle_rad, rho


def render_measure(job: tuple) -> dict:
    """Render one designed run (noise seed and start angle as given) and measure it with the
    designed-runs benchmark's options; its row."""
    seed, mu_range, drive_name, design, noise_seed, angle_rad, rho = job
    mu, mu_d = designed.draw(seed, mu_range)
    mu_d = mu_d if rho is None else rho * mu
    frames_n = int(round(design["record_s"] * design["fps_hz"])) + 1
    scn = random_scenario(seed, n_frames=max(frames_n, 1000))
    scn = replace(scn, ball=replace(scn.ball, mu=mu, mu_d=mu_d), seed=noise_seed,
                  drive=designed.staircase_drive(design, designed.DRIVES[drive_name]),
                  n_frames=frames_n, predicted_slip_s=None)
    state, _ = simulate_scenario(scn)
    state = dict(state, theta=state["theta"] + angle_rad)   # the whole motion turned
    pos = marker_positions(scn, state["theta"], state["beta"])
    frames = render_scenario_frames(scn, state, pos)
    row = {"seed": seed, "noise_seed": noise_seed, "angle_rad": angle_rad, "mu": mu,
           "mu_d": mu_d, "drive": drive_name, "mu_range": list(mu_range),
           "design": {k: design[k] for k in DESIGN_KEYS},
           "reflections": int(scn.lighting.reflections),
           "exposure_fraction": scn.optics.exposure_fraction}
    with tempfile.TemporaryDirectory() as tmp:
        rec = Path(tmp) / "rec.npy"
        np.save(rec, frames)
        args = ["measure", str(rec), "--out", str(Path(tmp) / "m"), "--quiet", "--no-plots",
                "--fps", repr(scn.fps), "--l", repr(scn.ball.l), "--d", repr(scn.ball.d)]
        if scn.lighting.reflections == 2:
            args += ["--ball-reflections", "2"]
        with redirect_stdout(io.StringIO()), redirect_stderr(io.StringIO()):
            row["exit"] = abu_main(args + designed.EXTRA_MEASURE_ARGS)
        if row["exit"] == 0:
            s = json.loads((Path(tmp) / "m" / "summary.json").read_text())
            row.update({k: s.get(k) for k in ("mu_low", "mu_high", "relative_width")})
    return row


def width_of(r: dict) -> float:
    """The measured relative width [-] (inf: a null bound or a failed measurement)."""
    w = r.get("relative_width")
    return float(w) if r.get("exit") == 0 and w is not None and r.get("mu_low") is not None \
        and r.get("mu_high") is not None else math.inf


def in_band(log_ratio: np.ndarray) -> np.ndarray:
    return (log_ratio >= LOG_BAND[0]) & (log_ratio <= LOG_BAND[1])


def plan_covariates(r: dict) -> dict[str, float]:
    """What the plan (and the draw) knows of a run: the width model's prediction at the true
    mu (expected and its mu_d / mu = 0.6 and 1 lanes), the stick stretch in ABU turns from the
    record's start to the planned slip, the speed there, the drive's lag."""
    from harness.planning.design_width import HZ, predict_run_width, staircase_motion
    from harness.planning.width_model import CALIBRATED
    from controller.reference import Staircase

    d, drive = r["design"], designed.DRIVES[r["drive"]]
    lanes = predict_run_width(d, drive, r["mu"], constants=replace(
        CALIBRATED, range_log_low=0.0, range_log_high=0.0))   # low90 / high90: the 0.6 / 1 lanes
    stair = Staircase(d["omega0_hz"] * HZ, d["omega_end_hz"] * HZ, d["t0_s"], d["te_s"],
                      d["step_hz"] * HZ, d["rounding"])
    t_s, theta_rad, omega_rad_s, _ = staircase_motion(drive, stair, d["fps_hz"], d["frames"])
    i = int(np.searchsorted(t_s, lanes["t_slip_s"] or t_s[-1]))
    i = min(i, t_s.size - 1)
    rho = r["mu_d"] / r["mu"]
    log_lanes = np.log([lanes["low90"], lanes["expected"], lanes["high90"]])
    return {"expected": lanes["expected"],
            "oracle_mu_d": float(np.exp(np.interp(rho, (0.6, 0.8, 1.0), log_lanes))),
            "mu_d/mu": rho, "stick turns": abs(theta_rad[i] - theta_rad[0]) / TWO_PI,
            "lag ms": 1e3 * drive.tau_motor, "reflections": float(r["reflections"]),
            "exposure": r["exposure_fraction"],
            "slip speed Hz": abs(omega_rad_s[i]) / TWO_PI,
            "mu in range": math.log(r["mu"] / r["mu_range"][0]) / math.log(
                r["mu_range"][1] / r["mu_range"][0])}


def bootstrap_share(groups: list[np.ndarray], stat: str, draws: int = 2000
                    ) -> tuple[float, float, float]:
    """Band share of ln(width / case centre) pooled over cases (centre: geometric mean or
    median), and its 5-95 % bootstrap range over cases (resampled with replacement)."""
    def share(gs: list[np.ndarray]) -> float:
        # a centre estimated from the same n recordings sits sqrt((n - 1) / n) closer to them
        # than the true one: deviations scaled back by sqrt(n / (n - 1))
        x = np.concatenate([(g - (g.mean() if stat == "mean" else np.median(g)))
                            * math.sqrt(g.size / (g.size - 1)) for g in gs])
        return float(in_band(x).mean())
    rng = np.random.default_rng(20261126)
    boots = [share([groups[j] for j in rng.integers(0, len(groups), len(groups))])
             for _ in range(draws)]
    return share(groups), float(np.percentile(boots, 5)), float(np.percentile(boots, 95))


def report_scatter(rows: dict[str, dict[int, list[dict]]], pop: dict[int, dict]) -> dict:
    """Print the within-case scatter per case and mode; return the pooled ln-width sd per
    mode."""
    pooled = {}
    print("\nwithin-case scatter of ln(width) (repeat 0 = the population's run; sd, 5-95 % of "
          "width / case geometric mean; ratio = measured / predicted):")
    for mode, cases in rows.items():
        groups, infinite = [], 0
        for seed, rs in cases.items():
            w = np.array([width_of(r) for r in rs])
            infinite += int(np.sum(~np.isfinite(w)))
            lw = np.log(w[np.isfinite(w)])
            groups.append(lw)
            x = lw - lw.mean()
            ex = pop[seed]["cov"]["expected"]
            print(f"  {mode:5s} seed {seed} {pop[seed]['drive']:15s} "
                  f"[{pop[seed]['mu_range'][0]:g}, {pop[seed]['mu_range'][1]:g}] "
                  f"mu_d/mu {pop[seed]['mu_d'] / pop[seed]['mu']:.2f}: n {lw.size}, width "
                  f"{100 * math.exp(lw.mean()):.1f} % (run 0 {100 * w[0]:.1f} %), sd "
                  f"{lw.std(ddof=1):.3f}, 5-95 % [{math.exp(np.percentile(x, 5)):.2f}, "
                  f"{math.exp(np.percentile(x, 95)):.2f}]; ratio run 0 {w[0] / ex:.2f}, case "
                  f"mean {math.exp(lw.mean()) / ex:.2f}, in band "
                  f"{100 * in_band(lw - math.log(ex)).mean():.0f} %")
        x_all = np.concatenate([g - g.mean() for g in groups])
        sd = math.sqrt(sum(float(np.sum((g - g.mean()) ** 2)) for g in groups)
                       / sum(g.size - 1 for g in groups))
        pooled[mode] = sd
        s_mean, lo_m, hi_m = bootstrap_share(groups, "mean")
        s_med, lo_d, hi_d = bootstrap_share(groups, "median")
        normal = math.erf(LOG_BAND[1] / (sd * math.sqrt(2.0)))
        # the symmetric band [1/f, f] around the case centre that holds 90 % of the recordings
        f90 = math.exp(float(np.percentile(np.abs(np.concatenate(
            [(g - g.mean()) * math.sqrt(g.size / (g.size - 1)) for g in groups])), 90)))
        print(f"  {mode:5s} pooled over {len(groups)} cases ({x_all.size} recordings, "
              f"{infinite} null bounds left out): sd of ln(width) {sd:.3f}, 5-95 % of width / "
              f"case geometric mean [{math.exp(np.percentile(x_all, 5)):.2f}, "
              f"{math.exp(np.percentile(x_all, 95)):.2f}]")
        print(f"  {mode:5s} best share within [0.77, 1.3]: predictor of the expected (case "
              f"geometric mean) {100 * s_mean:.1f} % (bootstrap over cases 5-95 % "
              f"[{100 * lo_m:.1f}, {100 * hi_m:.1f}]), of the median {100 * s_med:.1f} % "
              f"[{100 * lo_d:.1f}, {100 * hi_d:.1f}]; normal with the pooled sd "
              f"{100 * normal:.1f} %; the band holding 90 % at this scatter "
              f"[{1 / f90:.2f}, {f90:.2f}]")
    return pooled


def explained(y: np.ndarray, x: np.ndarray) -> float:
    """R^2 of the least-squares line of y on x."""
    if np.ptp(x) == 0:
        return 0.0
    return float(np.corrcoef(y, x)[0, 1] ** 2)


def report_population(pop: dict[int, dict], sd_within: float, sd_plan: float | None
                      ) -> None:
    """Print measured / predicted over the population and its split into within-case scatter
    and between-case error, with what each covariate explains of the latter."""
    rs = [r for r in pop.values() if math.isfinite(width_of(r))]
    y = np.array([math.log(width_of(r) / r["cov"]["expected"]) for r in rs])
    y_or = np.array([math.log(width_of(r) / r["cov"]["oracle_mu_d"]) for r in rs])
    v_tot, v_w = float(y.var(ddof=1)), sd_within ** 2
    v_b = max(v_tot - v_w, 0.0)
    print(f"\npopulation: {len(rs)} of {len(pop)} runs with finite bounds; ln(measured / "
          f"predicted): mean {y.mean():+.3f}, sd {math.sqrt(v_tot):.3f}, within [0.77, 1.3] "
          f"{100 * in_band(y).mean():.1f} %")
    print(f"  variance {v_tot:.4f} = within-case (scatter at fixed everything, sd "
          f"{sd_within:.3f}) {v_w:.4f} ({100 * v_w / v_tot:.0f} %) + between-case (the "
          f"predictor's error) {v_b:.4f} ({100 * v_b / v_tot:.0f} %); with the mean bias too: "
          f"mean square {v_tot + y.mean() ** 2:.4f}")
    if sd_plan is not None:
        v_mu_d = max(sd_plan ** 2 - v_w, 0.0)
        print(f"  of the between-case part: mu_d / mu unknown to any plan (sd at fixed plan "
              f"{sd_plan:.3f}) {v_mu_d:.4f} ({100 * v_mu_d / v_tot:.0f} % of all), the rest, "
              f"what a predictor could still learn, {max(v_b - v_mu_d, 0.0):.4f} "
              f"({100 * max(v_b - v_mu_d, 0.0) / v_tot:.0f} %)")
    print(f"  the width model at the true mu_d / mu (its lanes 0.6 / 0.8 / 1, interpolated in "
          f"ln): sd {y_or.std(ddof=1):.3f}, mean {y_or.mean():+.3f}, within [0.77, 1.3] "
          f"{100 * in_band(y_or).mean():.1f} %")
    print("  what explains ln(measured / predicted) (R^2 of a line; share of the between-case "
          "variance; Spearman rho):")
    from scipy.stats import spearmanr
    for name in ("mu_d/mu", "stick turns", "lag ms", "reflections", "exposure",
                 "slip speed Hz", "mu in range"):
        x = np.array([r["cov"][name] for r in rs])
        r2 = explained(y, x)
        rho = spearmanr(y, x)[0] if np.ptp(x) else 0.0
        print(f"    {name:14s} range [{x.min():.3g}, {x.max():.3g}]: R^2 {r2:.3f} "
              f"({100 * r2 * v_tot / max(v_b, 1e-12):.0f} % of between), Spearman "
              f"{rho:+.2f}")
    rho_x = np.array([r["cov"]["mu_d/mu"] for r in rs])
    hi = rho_x >= 0.9
    print(f"    mu_d/mu >= 0.9: {hi.sum()} runs, median ratio {math.exp(np.median(y[hi])):.2f}, "
          f"in band {100 * in_band(y[hi]).mean():.0f} %; < 0.9: {np.sum(~hi)} runs, median "
          f"{math.exp(np.median(y[~hi])):.2f}, in band {100 * in_band(y[~hi]).mean():.0f} %")


def population_rows(a: argparse.Namespace, designs: dict, pool: Pool | None) -> dict[int, dict]:
    """The population's rows: read from a ``bench_designed_runs --rows`` file or rendered."""
    if a.population_rows:
        rows = [json.loads(x) for x in Path(a.population_rows).read_text().splitlines() if x]
        return {r["seed"]: r for r in rows}
    jobs = []
    for s in range(a.first, a.first + a.population):
        rng_, dname = config_of(s, a.first)
        jobs.append((s, rng_, dname, designs[(rng_, dname)], s, 0.0, None))
    rows = pool.map(render_measure, jobs, chunksize=1) if pool else map(render_measure, jobs)
    return {r["seed"]: r for r in rows}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--first", type=int, default=1000, help="first seed of the population")
    ap.add_argument("--population", type=int, default=72, help="designed runs in the "
                    "population (seeds first ..)")
    ap.add_argument("--population-rows", default=None,
                    help="read the population from a bench_designed_runs.py --rows file "
                         "instead of rendering it (same seeds, same options)")
    ap.add_argument("--cases", type=int, nargs="+", default=list(DEFAULT_CASES),
                    help="seeds of the population re-rendered")
    ap.add_argument("--repeats", type=positive_int, default=10,
                    help="recordings per case and mode, the population's run included")
    ap.add_argument("--modes", nargs="+", default=list(MODES), choices=MODES)
    ap.add_argument("--jobs", type=int, default=1, help="worker processes")
    ap.add_argument("--rows", default=None, help="write every repeat's row here (JSON lines)")
    a = ap.parse_args()
    if a.repeats < 3:
        ap.error("--repeats must be >= 3")
    bad = [s for s in a.cases if not a.first <= s < a.first + a.population]
    if bad:
        ap.error(f"--cases {bad} outside the population {a.first}..{a.first + a.population - 1}")
    t0 = time.process_time()
    need = {config_of(s, a.first) for s in range(a.first, a.first + a.population)}
    designs = {c: designed.run_design(*c, []) for c in sorted(need)}
    pool = Pool(a.jobs) if a.jobs > 1 else None
    pop = population_rows(a, designs, pool)
    jobs = [(m, s, k, (s, *config_of(s, a.first), designs[config_of(s, a.first)],
                       *variant(m, s, k)))
            for m in a.modes for s in a.cases for k in range(1, a.repeats)]
    done = (pool.map(render_measure, [j[3] for j in jobs], chunksize=1) if pool
            else [render_measure(j[3]) for j in jobs])
    if pool:
        pool.close()
        pool.join()
    cpu_s = time.process_time() + sum(
        os.times()[2:4]) - t0   # children's CPU too (worker processes)
    for r in pop.values():
        r["cov"] = plan_covariates(r)
    rows: dict[str, dict[int, list[dict]]] = {m: {s: [pop[s]] for s in a.cases}
                                               for m in a.modes}
    for (m, s, _, _), r in zip(jobs, done):
        rows[m][s].append(r)
    if a.rows:
        Path(a.rows).write_text("".join(json.dumps({"mode": m, **r}) + "\n"
                                        for m in rows for rs in rows[m].values()
                                        for r in rs))
    print(f"designed runs: seeds {a.first}..{a.first + a.population - 1} "
          f"({'read from ' + a.population_rows if a.population_rows else 'rendered'}); cases "
          f"{', '.join(map(str, a.cases))}, {a.repeats} recordings per case and mode "
          f"({', '.join(a.modes)}); {len(jobs) + (0 if a.population_rows else a.population)} "
          f"rendered and measured in {cpu_s / 60:.1f} min CPU")
    pooled = report_scatter(rows, pop)
    if "noise" in pooled and "phase" in pooled:
        print(f"  noise and start angle add up (independent): sqrt(sd_noise^2 + sd_phase^2) = "
              f"{math.hypot(pooled['noise'], pooled['phase']):.3f}"
              + (f" against both at once {pooled['both']:.3f}" if "both" in pooled else ""))
    # the scatter at fixed everything: both at once, else noise and start angle in quadrature
    within = pooled.get("both") or math.hypot(pooled.get("noise", 0.0), pooled.get("phase", 0.0))
    if within > 0:
        report_population(pop, within, pooled.get("mu_d"))


if __name__ == "__main__":
    main()
