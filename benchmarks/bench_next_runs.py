"""Does ``abu next`` predict the combined width the measurement delivers? Chains of three runs.

Each case (one seed) draws a prior range (a factor of 2 wide) and drive as
``bench_designed_runs.py`` does, true mu log-uniform in the range and mu_d / mu uniform in
[0.6, 1], and the lighting, lens, sensor and set-up of ``twin.scenario.random_scenario(seed)``,
kept for all three runs of the case (one set-up, a new sensor noise per run). Then:

1. run 1: ``abu design`` for the range and drive, rendered and measured (``abu measure``);
2. ``abu next`` on run 1's summary -> ``predicted_combined_width`` P1 (expected, 90 % range);
   its proposal rendered and measured; ``abu measure-summary`` on runs 1-2 -> the measured
   combined interval (``common_range``) and its relative width M1;
3. ``abu next`` on runs 1-2 -> P2; run 3 rendered and measured; measure-summary of runs 1-3 ->
   M2.

Printed per slice: the share of M / P in [0.77, 1.3] after one and two runs, the share of M
inside next's predicted 90 % range, the coverage of the combined intervals, median widths and
the worst cases, and beside them the former rule on the same rows. ``next_run.POSITION_MEAN``
and ``POSITION_SD`` (where mu lies in a measured interval) were measured on seeds 0-47
(``--calibrate``); seeds 1000 on were not used for them. Run (two worker processes, nice;
15-20 s of CPU per case)::

    nice python benchmarks/bench_next_runs.py --cases 40 --first 1000 --jobs 2 --rows v.jsonl
    python benchmarks/bench_next_runs.py --report v.jsonl      # figures of saved rows
    python benchmarks/bench_next_runs.py --calibrate c.jsonl   # where mu lies (seeds 0-47)

``--camera VIEWS``: every run's lens calibrated on that many chessboard views and measured with
``abu measure --camera`` (``bench_designed_runs.py --camera``); ``abu next`` then predicts with
the calibration's lens prior, which the summaries state.
"""
from __future__ import annotations

import argparse
import io
import json
import math
import sys
import tempfile
import time
from contextlib import redirect_stderr, redirect_stdout
from dataclasses import replace
from multiprocessing import Pool
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np  # noqa: E402

from bench_designed_runs import CAMERA_VIEWS, DRIVES, RATIO_BAND, abu_main, configs, draw, \
    random_scenario, render_measure, run_design  # noqa: E402

#: offset of the sensor-noise seed of runs 2 and 3 (the scenario's set-up stays the seed's)
NOISE_SEED_STEP = 1_000_000


def _abu_json(args: list[str]) -> tuple[int, dict]:
    """Run an ``abu`` command with ``--json``; (exit status, its JSON or {})."""
    out = io.StringIO()
    with redirect_stdout(out), redirect_stderr(io.StringIO()):
        status = abu_main([*args, "--json"])
    return status, json.loads(out.getvalue()) if status == 0 else {}


def rel(lo: float, hi: float) -> float:
    """Relative width (hi - lo) / mid [-]."""
    return (hi - lo) / (0.5 * (hi + lo))


def case(job: tuple) -> dict:
    """One chain of three runs; its row (measured and predicted, per step)."""
    seed, mu_range, drive_name, design = job
    t_cpu = time.process_time()
    mu, mu_d = draw(seed, mu_range)
    scn = random_scenario(seed, n_frames=max(int(design["frames"]), 1000))
    scn = replace(scn, ball=replace(scn.ball, mu=mu, mu_d=mu_d))
    row: dict = {"seed": seed, "mu_range": list(mu_range), "drive": drive_name, "mu": mu,
                 "mu_d": mu_d, "reflections": int(scn.lighting.reflections), "runs": [],
                 "steps": []}
    with tempfile.TemporaryDirectory() as tmp:
        drive_json = Path(tmp) / "drive.json"
        drive_json.write_text(json.dumps(DRIVES[drive_name].to_dict()))
        summaries: list[str] = []
        for k in range(3):
            out = Path(tmp) / f"run{k + 1}"
            status, _, s = render_measure(replace(scn, seed=seed + k * NOISE_SEED_STEP),
                                          design, drive_name, out)
            row["runs"].append({"exit": status, "mu_low": s.get("mu_low"),
                                "mu_high": s.get("mu_high"),
                                "relative_width": s.get("relative_width"),
                                "design": {x: design[x] for x in (
                                    "omega0_hz", "omega_end_hz", "t0_s", "te_s", "rounding",
                                    "step_hz", "fps_hz", "frames", "record_s")}})
            if status != 0:
                break
            summaries.append(str(out / "m" / "summary.json"))
            if k > 0:   # what the measurement delivers after combining the runs
                st, comb = _abu_json(["measure-summary", *summaries, "--out",
                                      str(Path(tmp) / f"comb{k + 1}")])
                row["steps"][-1]["measured"] = comb.get("common_range") if st == 0 else None
            if k == 2:
                break
            st, nxt = _abu_json(["next", *summaries, "--drive", str(drive_json), "--no-check"])
            if st != 0:
                row["steps"].append({"next_exit": st})
                break
            row["steps"].append({"next_exit": 0, "current": nxt["current_interval"],
                                 "predicted": nxt["predicted_combined_width"],
                                 "at_mu": _combined_at(nxt, mu),
                                 "table": [[r[x] for x in ("mu", "expected", "low90", "high90")]
                                           for r in nxt["design"]["width_prediction"]["table"]]})
            design = nxt["design"]
    row["cpu_s"] = time.process_time() - t_cpu
    return row


def _combined_at(nxt: dict, mu: float) -> float:
    """next's combined-width rule evaluated at the true mu (its predicted measure width at mu
    interpolated in log mu over its table), for comparison with the mean over the range."""
    tab = nxt["design"]["width_prediction"]["table"]
    ms = np.array([r["mu"] for r in tab])
    ws = np.array([r["expected"] if r["expected"] is not None else 2.0 for r in tab])
    w = min(float(np.interp(math.log(mu), np.log(ms), ws)), 2.0)
    lo, hi = nxt["current_interval"]
    a, b = max(lo, mu * (1 - w / 2)), min(hi, mu * (1 + w / 2))
    return rel(a, b) if b > a else 0.0


def _now(step: dict) -> dict[str, float]:
    """next's predicted combined width for this step with the current rule (from the stored
    table of the proposal's predicted widths; the stored ``predicted`` is what next printed)."""
    from harness.planning.next_run import RANGE_QUANTILES, combined_width
    tab = np.array(step["table"], dtype=float)       # null (a null bound) -> nan
    return {key: combined_width(step["current"], tab[:, 0], np.nan_to_num(tab[:, j], nan=np.inf),
                                quantile=q)
            for j, (key, q) in enumerate(RANGE_QUANTILES.items(), start=1)}


def _former(step: dict) -> dict[str, float]:
    """The former rule: mean over next's log-spaced mu grid of [L, H] of [L, H] intersected
    with mu [1 - w/2, 1 + w/2] (mu anywhere in [L, H], the next interval centred on it)."""
    tab = np.array(step["table"], dtype=float)
    lo, hi = step["current"]
    out = {}
    for j, key in enumerate(("expected", "low90", "high90"), start=1):
        w = np.minimum(np.nan_to_num(tab[:, j], nan=2.0), 2.0)
        a, b = np.maximum(lo, tab[:, 0] * (1 - w / 2)), np.minimum(hi, tab[:, 0] * (1 + w / 2))
        out[key] = float(np.mean((b - a) / (0.5 * (a + b))))
    return out


def _figures(m: np.ndarray, p: dict[str, np.ndarray]) -> str:
    ratio = m / p["expected"]
    band = (ratio >= RATIO_BAND[0]) & (ratio <= RATIO_BAND[1])
    return (f"measured / predicted median {np.median(ratio):.3f}, 5-95 % "
            f"[{np.percentile(ratio, 5):.3f}, {np.percentile(ratio, 95):.3f}], within "
            f"[{RATIO_BAND[0]}, {RATIO_BAND[1]}]: {100 * band.mean():.1f} %, inside the "
            f"predicted 90 % range {100 * np.mean((m >= p['low90']) & (m <= p['high90'])):.1f} %")


def report(rows: list[dict], label: str, worst: int = 5) -> None:
    """Print the figures of one slice of cases."""
    print(f"{label}: {len(rows)} cases; run 1 with finite bounds in "
          f"{sum(r['runs'][0].get('mu_high') is not None for r in rows)}")
    for k in (0, 1):
        st = [(r, r["steps"][k]) for r in rows if len(r["steps"]) > k
              and r["steps"][k].get("measured") and r["steps"][k]["predicted"]["expected"]]
        print(f"  after {k + 1} run(s): {len(st)} complete, {len(rows) - len(st)} not "
              "(a null bound, next or measure failed)")
        if not st:
            continue
        m = np.array([rel(*s["measured"]) for _, s in st])
        now = [_now(s) for _, s in st]
        p = {key: np.array([x[key] for x in now]) for key in now[0]}
        old = [_former(s) for _, s in st]
        old = {key: np.array([x[key] for x in old]) for key in now[0]}
        cur = np.array([rel(*s["current"]) for _, s in st])
        print(f"    combined width, current rule: {_figures(m, p)}")
        at_mu = m / np.array([s["at_mu"] for _, s in st])
        print(f"    the former rule: {_figures(m, old)}; at the true mu (the next interval "
              f"centred on it, what no plan knows): median ratio {np.median(at_mu):.3f}, "
              f"within [{RATIO_BAND[0]}, {RATIO_BAND[1]}] "
              f"{100 * np.mean((at_mu >= RATIO_BAND[0]) & (at_mu <= RATIO_BAND[1])):.1f} %")
        own = np.array([r["runs"][k + 1]["relative_width"] / np.interp(
            math.log(r["mu"]), np.log(np.array(s["table"], float)[:, 0]),
            np.array(s["table"], float)[:, 1]) for r, s in st])
        print(f"    the next run's own width / its prediction at the true mu: median "
              f"{np.median(own):.3f}, within the band "
              f"{100 * np.mean((own >= RATIO_BAND[0]) & (own <= RATIO_BAND[1])):.1f} %")
        cov = np.mean([s["measured"][0] <= r["mu"] <= s["measured"][1] for r, s in st])
        print(f"    coverage of the combined interval {100 * cov:.1f} %; median widths: before "
              f"{100 * np.median(cur):.1f} %, predicted "
              f"{100 * np.median(p['expected']):.1f} %, measured {100 * np.median(m):.1f} %")
        order = np.argsort(-np.abs(np.log(m / p["expected"])))[:worst]
        print("    worst: " + "; ".join(
            f"seed {st[i][0]['seed']} {st[i][0]['drive']} mu {st[i][0]['mu']:.4g} mu_d/mu "
            f"{st[i][0]['mu_d'] / st[i][0]['mu']:.2f}: before {100 * cur[i]:.1f} %, predicted "
            f"{100 * p['expected'][i]:.1f} %, measured {100 * m[i]:.1f} %" for i in order))
    cpu = [r["cpu_s"] for r in rows if "cpu_s" in r]
    if cpu:
        print(f"  CPU time per case (three renders and measurements, two next): median "
              f"{np.median(cpu):.0f} s, max {np.max(cpu):.0f} s (shared machine)")


def calibrate(rows: list[dict]) -> None:
    """Print where the true mu lies in the combined interval before each next, as the fraction
    (mu - L) / (H - L): mean and standard deviation (next_run.POSITION_MEAN, POSITION_SD)."""
    for k in (0, 1):
        x = np.array([(r["mu"] - s["current"][0]) / (s["current"][1] - s["current"][0])
                      for r in rows if len(r["steps"]) > k for s in [r["steps"][k]]
                      if s.get("current")])
        print(f"after {k + 1} run(s), {x.size} cases: mu at the fraction {x.mean():.3f} "
              f"(sd {x.std(ddof=1):.3f}, 5-95 % {np.percentile(x, 5):.2f}-"
              f"{np.percentile(x, 95):.2f}) of the combined interval")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--first", type=int, default=1000, help="first seed")
    ap.add_argument("--cases", type=int, default=36, help="chains of three runs")
    ap.add_argument("--jobs", type=int, default=1, help="worker processes")
    ap.add_argument("--rows", default=None, help="write the rows as JSON lines here")
    ap.add_argument("--report", default=None, help="print the figures of saved rows and exit "
                                                   "(predicted with the current rule)")
    ap.add_argument("--calibrate", default=None, help="print where mu lies in the combined "
                                                      "intervals of saved rows and exit")
    ap.add_argument("--camera", type=int, default=0, metavar="VIEWS",
                    help="calibrate the lens on this many chessboard views and measure every "
                         "run with 'abu measure --camera' (abu next then reads the "
                         "calibration's lens prior from the summaries)")
    a = ap.parse_args()
    if a.camera:   # before the worker pool forks
        CAMERA_VIEWS.append(a.camera)
    if a.calibrate:
        calibrate([json.loads(x) for x in Path(a.calibrate).read_text().splitlines() if x])
        return
    if a.report:
        rows = [json.loads(x) for x in Path(a.report).read_text().splitlines() if x]
    else:
        cfg = configs()
        pick = [cfg[s % len(cfg)] for s in range(a.first, a.first + a.cases)]
        designs = {c: run_design(*c, []) for c in set(pick)}
        jobs = [(s, *c, designs[c]) for s, c in zip(range(a.first, a.first + a.cases), pick)]
        if a.jobs > 1:
            pool = Pool(a.jobs)
            rows = pool.map(case, jobs, chunksize=1)
            pool.close()
            pool.join()
        else:
            rows = [case(j) for j in jobs]
        if a.rows:
            Path(a.rows).write_text("".join(json.dumps(r) + "\n" for r in rows))
    seeds = [r["seed"] for r in rows]
    print(f"seeds {min(seeds)}..{max(seeds)}: ranges x drives of bench_designed_runs "
          f"({', '.join(DRIVES)}), true mu log-uniform in the range, mu_d/mu in [0.6, 1], "
          "set-up of twin.scenario.random_scenario(seed) for all three runs")
    report(rows, "all cases")


if __name__ == "__main__":
    main()
