"""The default analysis's CPU time recording by recording, and what sets it: the fit window.

``bench_measure.py`` times the whole ``abu measure`` on one recording (seed 1: a fit window of
about 800 samples). The model inference's noise model is dense in the fit window: its
Cholesky factor costs n^3, each model row's whitening n^2 / 2. Where the data never leave the
stick level by ``window_sigmas`` (a ball that slips a little and sticks again) the window is
the whole trusted record. This benchmark renders and tracks a slice of the harsh family
(``bench_width_floor.tracked``: the recordings of ``bench_width_floor.py --first F``) and
times the default analysis of each (``analyse_tracks`` with ``abu measure``'s defaults, CPU,
median of ``--repeat`` in-process runs after a warm-up) beside its peer, the same analysis with
the window cut to ``--cap`` samples (``InferenceOptions.max_fit_samples``; not the default: it
loses bounds, README). Printed per recording: the drive kind, the fit window's samples, both
CPU times and their ratio, and the interval with and without the cut where the cut moved it;
then the recordings whose window is longer than the cap against the rest::

    OPENBLAS_NUM_THREADS=1 nice python benchmarks/bench_analysis_time.py --first 14000 --n 48 \
        --jobs 2
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_args import map_jobs, positive_int  # noqa: E402
from bench_width_floor import summary, tracked  # noqa: E402

from measurement.inference import infer_mu  # noqa: E402
from measurement.inference.analysis import AnalysisOptions  # noqa: E402
from measurement.inference.infer_mu import InferenceOptions  # noqa: E402

#: set by main() before the workers fork
SETTINGS = {"cap": 1536, "repeat": 3}
#: fit-window lengths [samples] seen by the noise model in the current analysis
_WINDOWS: list[int] = []
_FIT_NOISE_MODEL = infer_mu._fit_noise_model


def _counting(win, *args, **kwargs):
    _WINDOWS.append(int(win.t.size))
    return _FIT_NOISE_MODEL(win, *args, **kwargs)


infer_mu._fit_noise_model = _counting   # the window's length, read where the model uses it


def _timed(scn, tracks, opt: AnalysisOptions) -> tuple[float, dict, int]:
    """(CPU seconds, summary, longest fit window [samples]) of one analysis."""
    _WINDOWS.clear()
    t0 = time.process_time()
    s = summary(scn, tracks, opt)
    return time.process_time() - t0, s, max(_WINDOWS, default=0)


def one(seed: int) -> dict:
    """Render, track and time one recording's analyses (default and cut, alternated)."""
    got = tracked(seed, None)
    if isinstance(got, int):
        return {"seed": seed, "error": got}
    scn, _, tracks, _ = got
    default = AnalysisOptions()
    cut = AnalysisOptions(inference=InferenceOptions(max_fit_samples=SETTINGS["cap"]))
    _timed(scn, tracks, default)   # warm-up: the first analysis in a process fills caches
    cpu = {"default": [], "cut": []}
    for _ in range(SETTINGS["repeat"]):
        for name, opt in (("default", default), ("cut", cut)):
            t, s, n = _timed(scn, tracks, opt)
            cpu[name].append(t)
            if name == "default":
                window, bounds = n, (s["mu_low"], s["mu_high"])
            else:
                bounds_cut = (s["mu_low"], s["mu_high"])
    return {"seed": seed, "kind": scn.drive.kind, "mu": scn.ball.mu, "window": window,
            "cpu": statistics.median(cpu["default"]), "cpu_cut": statistics.median(cpu["cut"]),
            "moved": bounds != bounds_cut, "bounds": bounds, "bounds_cut": bounds_cut}


def _bound(value: float | None) -> str:
    return "none" if value is None else f"{value:.4g}"


def report(rows: list[dict], cap: int) -> None:
    print(f"seed   kind          window  default CPU  cut to {cap}  ratio  "
          "interval moved by the cut")
    for r in rows:
        if "error" in r:
            print(f"{r['seed']:6d}  refused by the tracker (exit {r['error']})")
            continue
        moved = (f"yes: mu {r['mu']:.4g}, [{_bound(r['bounds'][0])}, "
                 f"{_bound(r['bounds'][1])}] -> [{_bound(r['bounds_cut'][0])}, "
                 f"{_bound(r['bounds_cut'][1])}]") if r["moved"] else "no"
        print(f"{r['seed']:6d}  {r['kind']:12s} {r['window']:6d}  {r['cpu']:8.2f} s  "
              f"{r['cpu_cut']:8.2f} s   {r['cpu'] / r['cpu_cut']:5.2f}  {moved}")
    ok = [r for r in rows if "error" not in r]
    for label, part in ((f"window over {cap} samples", [r for r in ok if r["window"] > cap]),
                        (f"window up to {cap} samples", [r for r in ok if r["window"] <= cap])):
        if not part:
            print(f"{label}: none")
            continue
        t = sorted(r["cpu"] for r in part)
        ratio = statistics.median(r["cpu"] / r["cpu_cut"] for r in part)
        print(f"{label}: {len(part)} of {len(ok)}; default analysis {t[0]:.2f}-{t[-1]:.2f} s "
              f"CPU (median {statistics.median(t):.2f} s), windows "
              f"{min(r['window'] for r in part)}-{max(r['window'] for r in part)} samples, "
              f"median ratio to the cut {ratio:.2f}, interval moved by the cut in "
              f"{sum(r['moved'] for r in part)}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--first", type=int, default=14000, help="first seed")
    ap.add_argument("--n", type=positive_int, default=48, help="recordings")
    ap.add_argument("--cap", type=positive_int, default=1536,
                    help="the peer's max_fit_samples (at least 256)")
    ap.add_argument("--repeat", type=positive_int, default=3,
                    help="timed runs of each analysis (median)")
    ap.add_argument("--jobs", type=positive_int, default=1, help="worker processes")
    a = ap.parse_args()
    if a.cap < 256:
        ap.error(f"--cap {a.cap}: expected at least 256 samples (InferenceOptions)")
    SETTINGS.update(cap=a.cap, repeat=a.repeat)
    t_wall = time.perf_counter()
    rows = map_jobs(one, range(a.first, a.first + a.n), a.jobs)
    report(rows, a.cap)
    print(f"seeds {a.first}..{a.first + a.n - 1}: {time.perf_counter() - t_wall:.0f} s wall "
          f"({a.jobs} worker process{'es' if a.jobs > 1 else ''}; CPU times are each "
          f"analysis' own)")


if __name__ == "__main__":
    main()
