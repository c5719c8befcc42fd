"""Whole-process time of ``abu measure`` on one 3072-frame recording, and where the time goes.

Renders one recording of the harsh twin (``twin.scenario.random_scenario(seed)``, 256 px,
3072 frames) as a multi-page TIFF, then times ``abu measure REC --out DIR`` with its default
settings as a fresh process (imports, read, track, analyse, uncertainty, plots), pinned to one
core (``taskset -c 0`` when available) -- median of ``--repeat`` (default 5) runs. The same
runs with ``--no-plots`` are alternated with them (the peer: the price of the figures). Then one
in-process run under ``cProfile`` splits the time into imports, reading, tracking, analysis
(kinematics, harmonics, running max, model inference) and plots.

    nice python benchmarks/bench_measure.py [--seed 1] [--repeat 5]
"""
from __future__ import annotations

import argparse
import cProfile
import os
import pstats
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def abu_cmd() -> list[str]:
    exe = Path(sys.executable).with_name("abu")
    base = [str(exe)] if exe.exists() else [sys.executable, "-m", "abu.cli.main"]
    if shutil.which("taskset"):
        base = ["taskset", "-c", "0"] + base
    return base


def timed(cmd: list[str]) -> float:
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                   env={**os.environ, "OPENBLAS_NUM_THREADS": "1"})
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    from twin.scenario import random_scenario, render_scenario

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        scn = random_scenario(args.seed)
        render_scenario(tmp / "rec", scn)
        rec = tmp / "rec" / "frames.tif"
        refl = ["--ball-reflections", "2"] if scn.lighting.reflections == 2 else []
        base = abu_cmd() + ["measure", str(rec), "--out", str(tmp / "out"), "--overwrite",
                            "--quiet"] + refl
        whole, noplot = [], []
        for _ in range(args.repeat):              # alternate the two, several pairs
            whole.append(timed(base))
            noplot.append(timed(base + ["--no-plots"]))
        print(f"abu measure on {scn.n_frames} frames ({scn.width}x{scn.height} px, seed "
              f"{args.seed}, {scn.lighting.reflections} reflection(s)), whole process, one core:")
        print(f"  default settings (with plots): median {statistics.median(whole):.2f} s "
              f"(runs {', '.join(f'{t:.2f}' for t in whole)})")
        print(f"  --no-plots (peer):             median {statistics.median(noplot):.2f} s "
              f"(runs {', '.join(f'{t:.2f}' for t in noplot)}); plots cost "
              f"{statistics.median(whole) - statistics.median(noplot):.2f} s")
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-c", "import abu.cli.main"], check=True)
        print(f"  'import abu.cli.main' alone: {time.perf_counter() - t0:.2f} s (fresh process)")

        # where the time goes: one in-process run under cProfile (imports included)
        prof = cProfile.Profile()
        prof.enable()
        from abu.cli.main import main as abu_main
        abu_main(["measure", str(rec), "--out", str(tmp / "out2"), "--quiet"] + refl)
        prof.disable()
        st = pstats.Stats(prof)
        total = st.total_tt
        parts = {
            "read recording": ["frames_io.py:read_recording"],
            "tracking": ["tracking.py:track_recording", "reflections.py:track_markers"],
            "analysis (all)": ["analysis.py:analyse_tracks"],
            "  kinematics": ["kinematics.py:savgol_kinematics"],
            "  harmonic removal": ["harmonic.py:remove_harmonic"],
            "  running-max interval": ["interval.py:slip_interval"],
            "  model inference": ["inference.py:infer_mu"],
            "plots": ["plots.py:plot_analysis"],
            "CSV text": ["cli.py:format_table_csv", "tracks_io.py:format_tracks_csv"],
        }
        cum = {}
        for (fname, _line, func), v in st.stats.items():
            key = f"{Path(fname).name}:{func}"
            cum[key] = max(cum.get(key, 0.0), v[3])
        print(f"  in-process profile (total {total:.2f} s incl. imports and profiler overhead):")
        for label, keys in parts.items():
            print(f"    {label:<24s} {sum(cum.get(k, 0.0) for k in keys):6.3f} s")


if __name__ == "__main__":
    main()
