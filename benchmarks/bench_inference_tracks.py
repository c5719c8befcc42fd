"""Coverage of the model-based set ALONE (summary ``model_fit``) on the tracks-level family.

The family of ``tests/test_inference.py`` (harsh-twin drives of ``twin.scenario``
simulated on the exact plant, camera geometry, white tracking noise and a lighting shift of the
ball's apparent centre with harmonics 1-3 of its angle), fast (~0.3-0.5 s a recording), for
trying noise models of :mod:`measurement.inference.infer_mu` before the rendered benchmark
(``bench_coverage.py``). Options of :class:`measurement.inference.infer_mu.InferenceOptions` as JSON.

Run::

    nice python benchmarks/bench_inference_tracks.py --n 60
    nice python benchmarks/bench_inference_tracks.py --n 60 \\
        --options '{"noise_model": "leftover", "kinematic_sigma_scale": 2.8}'
"""
from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]

import numpy as np  # noqa: E402

from measurement.inference.analysis import AnalysisOptions, analyse_tracks  # noqa: E402
from measurement.inference.infer_mu import InferenceOptions  # noqa: E402
from test_inference import scenario_tracks  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--first", type=int, default=0)
    ap.add_argument("--n", type=int, default=60)
    ap.add_argument("--options", default="{}", help="InferenceOptions fields as JSON")
    ap.add_argument("--verbose", action="store_true", help="one line per recording")
    a = ap.parse_args()
    opt = AnalysisOptions(inference=InferenceOptions(**json.loads(a.options)))
    rows = []
    for seed in range(a.first, a.first + a.n):
        times, x, y, ball, state = scenario_tracks(seed)
        _, s = analyse_tracks(times, x, y, l=ball.l, d=ball.d, options=opt)
        mf, mu = s["model_fit"], ball.mu
        lo, hi = mf["mu_low"], mf["mu_high"]
        inside = (lo is None or lo <= mu) and (hi is None or mu <= hi)
        miss = 0.0 if inside else max((lo or 0.0) - mu, mu - (hi if hi is not None else 9)) / mu
        width = None if lo is None or hi is None else (hi - lo) / (0.5 * (hi + lo))
        rows.append({"seed": seed, "inside": inside, "miss": miss, "width": width})
        if a.verbose:
            print(json.dumps({**rows[-1], "mu": mu, "mu_d": ball.mu_dynamic, "lo": lo, "hi": hi,
                              "status": mf["status"]}), flush=True)
    widths = [r["width"] for r in rows if r["width"] is not None]
    print(f"model-based set alone, tracks-level harsh family, seeds {a.first}..{a.first + a.n - 1}"
          f" (2400 frames), options {a.options}: coverage of the stated 95 % "
          f"{100 * np.mean([r['inside'] for r in rows]):.1f} %, missing mu by > 2 %: "
          f"{sum(r['miss'] > 0.02 for r in rows)}, worst miss "
          f"{100 * max(r['miss'] for r in rows):.1f} %, median relative width "
          f"{100 * np.median(widths):.1f} %, 90th percentile {100 * np.percentile(widths, 90):.1f}"
          f" %, a bound null in {len(rows) - len(widths)}")


if __name__ == "__main__":
    main()
