"""Whole-process time of ``abu measure`` on one 3072-frame recording against the recording's
duration, and where the time goes.

Renders one recording of the harsh twin (``twin.scenario.random_scenario(seed)``, 256x256 px,
3072 frames at 4500 frames/s = 0.683 s) as a multi-page TIFF (what ``abu render`` writes), then
runs ``abu measure REC --out DIR`` with its default settings as a fresh process (imports, read,
track, analyse, uncertainty, write, figures), pinned to one core (``taskset -c 0`` when
available, one BLAS thread), ``--repeat`` times (default 5), alternating with the same command
with ``--no-plots`` (the peer: the price of the figures). For every run it prints the wall
time and the child's CPU time (user + sys, ``getrusage(RUSAGE_CHILDREN)``; on a machine other
people load, the CPU time is the figure to compare), their medians and the ratio to the
recording's duration (the targets of issue 20: <= 1.0x without figures, <= 1.5x with them, on
an idle core). The children cache their compiled modules (``PYTHONPYCACHEPREFIX`` in the
temporary folder), as an installed package does; when the environment sets
PYTHONDONTWRITEBYTECODE, three more ``--no-plots`` runs show the price of compiling every
module at each start.

Then one in-process run, timed stage by stage with ``time.process_time`` (no profiler
overhead): imports, reading, finding the markers, tracking, analysis (and its parts: the
lighting harmonics, the running maximum, the model inference with its slip model, noise
model factor and whitening), writing the CSV/JSON, importing matplotlib and drawing the
figures (Agg drawing and PNG encoding apart).

    python benchmarks/bench_measure.py [--seed 1] [--repeat 5]     (on an idle machine)
    python benchmarks/bench_measure.py --repeat 3 --busy 2   (+ the price of BLAS threads on a
                                                              busy machine)
"""
from __future__ import annotations

import argparse
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

STAGES = r'''
import sys, time, tempfile
T = time.process_time
from abu.cli.figure_startup import install
install()   # as the abu program does at its start (matplotlib's set() docstrings skipped)
t0 = T()
import numpy as np
from measurement import pipeline
from measurement.imaging.frames_io import read_recording
from measurement.imaging.markers import find_markers
from measurement.imaging.reflections import track_markers
from measurement.inference.analysis import analyse_tracks
t_imp = T() - t0
rec_path, refl = sys.argv[1], int(sys.argv[2])
out = {"imports (measurement, numpy)": t_imp}
t = T(); from abu.cli.main import build_parser; build_parser("measure")
out["imports: abu command line + 'measure' parser"] = T() - t
t = T(); rec = read_recording(rec_path); out["read recording (incl. tifffile import)"] = T() - t
t = T(); seeds, _ = find_markers(np.asarray(rec.frames[0]), ball_reflections=refl)
out["find markers (frame 0, incl. cv2 import)"] = T() - t
t = T(); tracks = track_markers(rec.frames, seeds, ball_reflections=refl)
out["tracking"] = T() - t
t = T(); mt = pipeline.track_recording(rec_path, settings=pipeline.TrackingSettings(
    ball_reflections=refl))
pipe_track = T() - t
from measurement.imaging.compression import detect
t = T(); detect(rec.frames, rec.codec)
out["compression check (its part of the pipeline)"] = T() - t

# the analysis' parts: CPU time inside a few functions, by wrappers (no profiler)
from measurement.inference import noise_models, profile_cache, infer_mu, running_max
from measurement.inference import analysis as an
from measurement.kinematics import harmonic
inner = {}
def timed(owner, name, label):
    f = getattr(owner, name)
    def wrap(*a, **k):
        t = T()
        try:
            return f(*a, **k)
        finally:
            inner[label] = inner.get(label, 0.0) + T() - t
    setattr(owner, name, wrap)
timed(profile_cache, "slip_displacement", "slip model (episodes)")
timed(noise_models.Gls, "whiten", "whitening (forward substitution)")
timed(noise_models, "leftover_whitener_of", "noise model: Cholesky factor")
timed(an.inference_mod, "infer_mu", "model inference (infer_mu)")
timed(an.interval_mod, "slip_interval", "running max + creep bound")
timed(an.harmonic_mod, "remove_harmonic", "lighting harmonics")
t = T(); res = pipeline.measure_tracks(mt); out["analysis + uncertainty"] = T() - t
nested = {"slip model (episodes)", "whitening (forward substitution)",
          "noise model: Cholesky factor"}
for k, v in inner.items():
    out[("    of which " if k in nested else "  of which ") + k] = v
d = tempfile.mkdtemp()
t = T(); pipeline.write_measurement(res, d, plots=False); out["write CSV + JSON"] = T() - t
t = T(); import matplotlib.figure, matplotlib.backends.backend_agg
out["figures: import matplotlib"] = T() - t
from measurement.report import plots
import abu_model.figure_files as ff
from matplotlib.backends.backend_agg import FigureCanvasAgg
timed(FigureCanvasAgg, "draw", "draw (Agg)")
timed(ff, "_png_bytes", "png")
t = T(); plots.plot_analysis(res.table, res.summary, d)
out["figures: build + draw + PNG"] = T() - t
out["  of which draw (Agg)"] = inner.get("draw (Agg)", 0.0)
out["  of which encode PNG"] = inner.get("png", 0.0) - inner.get("draw (Agg)", 0.0)
# matplotlib's floor: the same two canvases (3 panels each, 150 dpi, the same PNG writer)
# with one plain curve a panel and one axis label -- no legends, titles, bands or markers
def bare_pair():
    for size in ((7.5, 9.0), (8.0, 8.4)):
        fig = matplotlib.figure.Figure(figsize=size)
        FigureCanvasAgg(fig)
        for ax in fig.subplots(3, 1):
            ax.plot(res.table["time_s"], res.table["theta_rad"])
            ax.set_ylabel("theta [rad]")
        ff._png_bytes(fig)
t = T(); bare_pair(); out["  matplotlib's floor: two bare 3-panel figures"] = T() - t
for k, v in out.items():
    print(f"{k}\t{v}")
print(f"(read + markers + tracking + gap filling through the pipeline: {pipe_track:.3f} s)",
      file=sys.stderr)
'''


def abu_cmd() -> list[str]:
    exe = Path(sys.executable).with_name("abu")
    base = [str(exe)] if exe.exists() else [sys.executable, "-m", "abu.cli.main"]
    if shutil.which("taskset"):
        base = ["taskset", "-c", "0"] + base
    return base


def child_env(pycache: Path | None) -> dict:
    """The children's environment: one BLAS thread, this checkout first on the path, and the
    compiled modules cached in ``pycache`` as an installed package has them (pip compiles on
    install; a checkout run with PYTHONDONTWRITEBYTECODE=1 compiles every module of the
    project at each start, ~0.06 s more). ``pycache`` None: no bytecode written or read
    from a cache folder (the environment's own setting)."""
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1",
           "PYTHONPATH": str(ROOT)}
    if pycache is not None:
        env.pop("PYTHONDONTWRITEBYTECODE", None)
        env["PYTHONPYCACHEPREFIX"] = str(pycache)
    return env


def timed(cmd: list[str], env: dict) -> tuple[float, float]:
    """(wall, CPU user + sys) seconds of one run of ``cmd`` as a child process."""
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                   env=env)
    wall = time.perf_counter() - t0
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)


def _line(label: str, runs: list[tuple[float, float]], duration: float) -> str:
    wall = statistics.median(r[0] for r in runs)
    cpu = statistics.median(r[1] for r in runs)
    return (f"  {label:<26s} wall median {wall:.3f} s = {wall / duration:.2f} x recording; "
            f"CPU median {cpu:.3f} s = {cpu / duration:.2f} x recording\n"
            f"  {'':<26s} (wall runs {', '.join(f'{r[0]:.2f}' for r in runs)}; "
            f"CPU runs {', '.join(f'{r[1]:.2f}' for r in runs)})")


def _busy_machine(cmd: list[str], env: dict, duration: float, args) -> None:
    """``cmd`` (not pinned to a core) beside ``args.busy`` spinning processes, alternating one
    BLAS thread (what ``abu`` sets) with one per core (OpenBLAS's default): a shared lab
    machine or a sweep's other workers."""
    if cmd[0] == "taskset":
        cmd = cmd[3:]
    spin = [subprocess.Popen([sys.executable, "-c", "while True: pass"])
            for _ in range(args.busy)]
    try:
        runs: dict[str, list[tuple[float, float]]] = {"1": [], str(os.cpu_count() or 2): []}
        for _ in range(args.repeat):
            for n in runs:
                runs[n].append(timed(cmd, {**env, "OPENBLAS_NUM_THREADS": n}))
    finally:
        for p in spin:
            p.kill()
    print(f"  --no-plots beside {args.busy} busy processes (not pinned):")
    for n, r in runs.items():
        print(_line(f"OPENBLAS_NUM_THREADS={n}:", r, duration))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--busy", type=int, default=0,
                    help="also time --no-plots with N busy processes beside it, one BLAS "
                         "thread (abu's default) against as many as cores (OpenBLAS's own)")
    ap.add_argument("--two-lighting-models", action="store_true",
                    help="also time --no-plots --lighting-models two in the same alternation")
    args = ap.parse_args()
    from twin.scenario import random_scenario, render_scenario

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        scn = random_scenario(args.seed)
        render_scenario(tmp / "rec", scn)
        rec = tmp / "rec" / "frames.tif"
        duration = scn.n_frames / scn.fps
        refl = ["--ball-reflections", "2"] if scn.lighting.reflections == 2 else []
        base = abu_cmd() + ["measure", str(rec), "--out", str(tmp / "out"), "--overwrite",
                            "--quiet"] + refl
        env = child_env(tmp / "pycache")
        timed(base, env)                          # warm the page cache and the .pyc files
        whole, noplot, two = [], [], []
        for _ in range(args.repeat):              # alternate the two, several pairs
            whole.append(timed(base, env))
            noplot.append(timed(base + ["--no-plots"], env))
            if args.two_lighting_models:
                two.append(timed(base + ["--no-plots", "--lighting-models", "two"], env))
        plain = child_env(None)
        nocache = [timed(base + ["--no-plots"], plain) for _ in range(3)] \
            if plain.get("PYTHONDONTWRITEBYTECODE") else []
        print(f"abu measure on {scn.n_frames} frames ({scn.width}x{scn.height} px, "
              f"{scn.fps:g} frames/s = {duration:.3f} s recorded; seed {args.seed}, "
              f"{scn.lighting.reflections} reflection(s)), whole process, one core, "
              f"{args.repeat} alternated pairs:")
        print(_line("default (with figures):", whole, duration))
        print(_line("--no-plots (peer):", noplot, duration))
        print(f"  figures cost {statistics.median(r[1] for r in whole) - statistics.median(r[1] for r in noplot):.3f} s CPU "
              f"(median difference)")
        if two:
            print(_line("--no-plots --lighting-models two:", two, duration))
        if nocache:
            print(_line("--no-plots, no .pyc:", nocache, duration))
            print("  (PYTHONDONTWRITEBYTECODE is set here: every module of the project "
                  "compiled at each start, unlike an installed package)")
        if args.busy > 0:
            _busy_machine(base + ["--no-plots"], env, duration, args)
        start = timed([sys.executable, "-c", "import abu.cli.main"], env)
        print(f"  'import abu.cli.main' alone (fresh process): wall {start[0]:.3f} s, "
              f"CPU {start[1]:.3f} s")
        _teardown(env, args.repeat)

        # where the time goes: one in-process run, stage by stage (CPU time, no profiler)
        cmd = (["taskset", "-c", "0"] if shutil.which("taskset") else []) + [
            sys.executable, "-c", STAGES, str(rec), str(scn.lighting.reflections)]
        proc = subprocess.run(cmd, check=True, capture_output=True, text=True, env=env)
        print("  stages of one in-process run (CPU time, process_time):")
        total = 0.0
        for row in proc.stdout.strip().splitlines():
            name, value = row.split("\t")
            total += 0.0 if name.startswith(" ") else float(value)   # parts: not summed
            print(f"    {name:<44s} {float(value):6.3f} s = {float(value) / duration:5.2f} x "
                  "recording")
        print(f"    {'sum':<44s} {total:6.3f} s (interpreter start-up not included)")
        stage = dict(r.split("\t") for r in proc.stdout.strip().splitlines())
        floor = (statistics.median(r[1] for r in noplot)
                 + float(stage["figures: import matplotlib"])
                 + float(stage["  matplotlib's floor: two bare 3-panel figures"]))
        print(f"  floor with matplotlib figures: --no-plots CPU median + matplotlib's import + "
              f"two bare 3-panel figures = {floor:.3f} s = {floor / duration:.2f} x recording "
              f"(issue 20's target with figures: 1.5 x)")
        print("    " + proc.stderr.strip())


def _teardown(env: dict, repeat: int) -> None:
    """CPU time of the interpreter's module teardown that ``abu``'s exit skips
    (:mod:`abu.cli.process_exit`): a process that loads NumPy and matplotlib and draws a
    figure, ended by ``sys.exit`` and by ``exit_process``, alternated."""
    load = ("import numpy; from matplotlib.figure import Figure; "
            "from matplotlib.backends.backend_agg import FigureCanvasAgg; f = Figure(); "
            "FigureCanvasAgg(f); f.subplots(3, 1); f.canvas.draw()")
    fast = load + "; from abu.cli.process_exit import exit_process; exit_process(0)"
    pin = ["taskset", "-c", "0"] if shutil.which("taskset") else []
    diffs = [timed(pin + [sys.executable, "-c", load], env)[1]
             - timed(pin + [sys.executable, "-c", fast], env)[1] for _ in range(repeat)]
    print(f"  interpreter teardown that abu's exit skips (numpy + matplotlib loaded): "
          f"{statistics.median(diffs):.3f} s CPU (median of {repeat} alternated pairs)")


if __name__ == "__main__":
    main()
