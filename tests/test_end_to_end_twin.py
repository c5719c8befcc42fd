"""End to end on the digital twin: co-simulated experiment -> rendered frames -> tracking ->
analysis. The true mu is known, so the coverage of the intervals is measured, not assumed.

Cost control (the whole suite must stay well under 15 minutes on 2 cores): the experiment is
simulated once and rendered once without sensor noise; only the noise differs between the 50
recordings, and it is drawn only where the tracker looks: in a box of +-26 px around each
marker's true position in each frame (the tracker reads 30 px windows within ~3 px of it), with
the renderer's noise model (Gaussian, sigma = RenderSettings.noise_sigma grey levels, rounded
and clipped to 8 bits). The clean frames are therefore quantised once before the noise is added
(a frozen 1/sqrt(12)-grey-level pattern, ~1e-4 px on a centre: negligible beside the 0.007 px
tracking noise). Each recording is the first 1800 frames (0.40 s at 4500 frames/s) of the
report's 3072: the ball slips at 0.20 s and sticks again at 0.37 s, so later frames (more stick)
add nothing to the interval. The recordings are tracked and analysed in two processes. The
second test renders a full recording with ``abu render`` and measures it with ``abu measure``.
"""
from __future__ import annotations

import json
import math
import os
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context

import numpy as np
import pytest

from twin import report_twin as twin  # noqa: E402  (a broken import must fail, not skip)

#: The README's figure for this test (median relative width of the 50 intervals).
README_MEDIAN_WIDTH = 0.138
N_FRAMES = 1800
N_RECORDINGS = 50
REPORT_SINGLE_RUN_WIDTH = (0.0312 - 0.0286) / (0.5 * (0.0312 + 0.0286))  # 8.7 %

BOX = 26  # half-size of the noisy box around each marker [px]

_WORK: dict = {}


def _init(clean_path, positions, noise_sigma, times, l, d):
    _WORK.update(clean=np.load(clean_path, mmap_mode="r"), positions=positions,
                 noise=noise_sigma, times=times, l=l, d=d)


def noisy_frames(clean: np.ndarray, positions, noise_sigma: float, seed: int) -> np.ndarray:
    """``clean`` with sensor noise drawn in a box around each marker of each frame."""
    frames = np.array(clean)
    n, h, w = frames.shape
    rng = np.random.default_rng(seed)
    offs = np.arange(-BOX, BOX + 1)
    for p in positions:
        rows = np.clip(np.rint(p[:, 1]).astype(int)[:, None] + offs[None, :], 0, h - 1)
        cols = np.clip(np.rint(p[:, 0]).astype(int)[:, None] + offs[None, :], 0, w - 1)
        idx = (np.arange(n)[:, None, None], rows[:, :, None], cols[:, None, :])
        patch = frames[idx].astype(np.float32)
        patch += noise_sigma * rng.standard_normal(patch.shape, dtype=np.float32)
        frames[idx] = np.clip(np.rint(patch), 0, 255).astype(np.uint8)
    return frames


def _one_recording(seed: int) -> dict:
    """Noise seed ``seed`` on the clean frames, tracking from the true frame-0 seeds, analysis."""
    from measurement.inference.analysis import AnalysisOptions, analyse_tracks
    from measurement.imaging.tracking import track_recording

    c, cd, ball = _WORK["positions"]
    frames = noisy_frames(_WORK["clean"], (c, cd, ball), _WORK["noise"], seed)
    tracks = track_recording(frames, np.stack([c[0], cd[0], ball[0]]))
    _, s = analyse_tracks(_WORK["times"], tracks.x, tracks.y, lost=tracks.lost, l=_WORK["l"],
                          d=_WORK["d"], options=AnalysisOptions(mc_draws=0))
    return {"seed": seed, "mu_low": s["mu_low"], "mu_high": s["mu_high"],
            "t_slip_low": s["t_slip_low"], "t_slip_high": s["t_slip_high"],
            "relative_width": s["relative_width"], "status": s["status"],
            "sigma_px": s["noise"]["sigma_px"], "lost": s["lost_frames"]["any"]}


@pytest.fixture(scope="module")
def simulated(fmu_dir):
    settings = twin.TwinSettings(n_frames=N_FRAMES)
    state, positions, result = twin.simulate_twin(settings, fmu_dir=fmu_dir)
    return settings, state, positions, result


def test_noise_boxes_reproduce_the_renderers_noise(simulated):
    from twin.render import render_frames
    settings, _, positions, _ = simulated
    c, cd, ball = (p[:3] for p in positions)
    clean = render_frames(c, cd, ball, settings.render.with_(noise_sigma=0.0), seed=0)
    full = render_frames(c, cd, ball, settings.render, seed=3)
    boxed = noisy_frames(clean, (c, cd, ball), settings.render.noise_sigma, 3)
    # Around the CD marker both have the renderer's noise level and the same mean image (the
    # first 3 frames: the marker moves 2.7 px per frame).
    x0, y0 = (int(round(v)) for v in cd[0])
    sl = (slice(0, 3), slice(y0 - 12, y0 + 13), slice(x0 - 12, x0 + 13))
    r_full = full[sl].astype(float) - clean[sl]
    r_box = boxed[sl].astype(float) - clean[sl]
    assert np.std(r_box) == pytest.approx(np.std(r_full), rel=0.05)
    assert abs(np.mean(r_box) - np.mean(r_full)) < 0.05


def test_intervals_from_rendered_recordings_contain_the_true_mu(simulated, record_property,
                                                                tmp_path):
    from twin.render import render_frames
    settings, state, positions, result = simulated
    mu = settings.mu
    t_slip = result.summary["t_slip"]
    assert t_slip is not None and 0.1 < t_slip < 0.3      # the ball slips inside the record
    clean_path = tmp_path / "clean.npy"
    np.save(clean_path, render_frames(*positions, settings.render.with_(noise_sigma=0.0), seed=0))
    saved = os.environ.get("OPENBLAS_NUM_THREADS")
    # Small dense algebra is ~10x faster single-threaded on a shared 2-core machine; the
    # spawned workers read this when they import NumPy.
    os.environ["OPENBLAS_NUM_THREADS"] = "1"
    try:
        with ProcessPoolExecutor(max_workers=2, mp_context=get_context("spawn"),
                                 initializer=_init,
                                 initargs=(clean_path, positions, settings.render.noise_sigma,
                                           settings.frame_times, settings.ball.l,
                                           settings.ball.d)) as pool:
            runs = list(pool.map(_one_recording, range(1000, 1000 + N_RECORDINGS)))
    finally:
        if saved is None:
            os.environ.pop("OPENBLAS_NUM_THREADS", None)
        else:
            os.environ["OPENBLAS_NUM_THREADS"] = saved

    contained = [r["mu_low"] is not None and r["mu_high"] is not None
                 and r["mu_low"] <= mu <= r["mu_high"] for r in runs]
    widths = [r["relative_width"] for r in runs if r["relative_width"] is not None]
    median_width = float(np.median(widths))
    coverage = float(np.mean(contained))
    record_property("coverage", coverage)
    record_property("median_relative_width", median_width)
    print(f"\ntwin, {N_RECORDINGS} recordings, true mu = {mu}: coverage {coverage:.0%}, median "
          f"relative width {median_width:.1%} (report, one run: {REPORT_SINGLE_RUN_WIDTH:.1%}); "
          f"median interval [{np.median([r['mu_low'] for r in runs]):.5f}, "
          f"{np.median([r['mu_high'] for r in runs]):.5f}]; tracking noise "
          f"{np.median([np.mean(r['sigma_px']) for r in runs]):.4f} px")
    assert all(r["lost"] == 0 for r in runs)
    # informative: every run gives both bounds (a null bound is no hit), coverage >= 95 %
    assert all(r["mu_low"] is not None and r["mu_high"] is not None for r in runs), runs
    assert coverage >= 0.95, [r for r, ok in zip(runs, contained) if not ok]
    # The onset bracket holds the simulated slip instant (a null end is no claim, but at most
    # a few may be null).
    both = [r for r in runs if r["t_slip_low"] is not None and r["t_slip_high"] is not None]
    assert len(both) >= 0.9 * len(runs)
    assert all(r["t_slip_low"] <= t_slip <= r["t_slip_high"] for r in both), \
        [(r["t_slip_low"], r["t_slip_high"]) for r in both]
    # The width the README quotes (13.8 %), within the spread of this figure between machines
    # and versions; a doubled width or a biased marker fails here.
    assert median_width < 1.15 * README_MEDIAN_WIDTH, median_width


def truth_tracks_csv(folder, path):
    """A tracks CSV from the twin's truth.csv (the true marker centres)."""
    lines = (folder / "truth.csv").read_text().splitlines()
    head = lines[0].split(",")
    cols = ["time_s", "x_center_px", "y_center_px", "x_cd_px", "y_cd_px", "x_ball_px",
            "y_ball_px"]
    idx = [head.index(c) for c in cols]
    rows = ["time,x_center,y_center,x_cd,y_cd,x_ball,y_ball"]
    for line in lines[1:]:
        cells = line.split(",")
        rows.append(",".join(cells[i] for i in idx))
    path.write_text("\n".join(rows) + "\n")
    return path


def test_render_then_measure_with_the_command_line(tmp_path, capsys):
    from abu.cli.main import main

    rec = tmp_path / "twin"
    assert main(["render", "--out", str(rec), "--frames", str(N_FRAMES), "--seed", "7",
                 "--quiet"]) == 0
    meta = json.loads((rec / "meta.json").read_text())
    mu = meta["mu"]
    assert (rec / "frames.tif").stat().st_size > N_FRAMES * 256 * 256

    # The true coordinates, analysed from a tracks CSV.
    csv_path = truth_tracks_csv(rec, tmp_path / "truth_tracks.csv")
    out_true = tmp_path / "from_truth"
    assert main(["measure", str(csv_path), "--tracks", "--out", str(out_true), "--json",
                 "--mc-draws", "0", "--no-plots", "--quiet"]) == 0
    s_true = json.loads(capsys.readouterr().out)
    assert s_true["mu_low"] <= mu <= s_true["mu_high"], (s_true["mu_low"], s_true["mu_high"])

    # The rendered frames: markers found automatically, tracked, analysed, figures written.
    out = tmp_path / "measured"
    assert main(["measure", str(rec / "frames.tif"), "--out", str(out), "--json",
                 "--mc-draws", "4"]) == 0
    captured = capsys.readouterr()
    s = json.loads(captured.out)
    assert "centre (" in captured.err            # says which marker is which
    assert s["mu_low"] <= mu <= s["mu_high"]
    # The seeds found agree with the twin's frame-0 positions.
    found = np.array([[float(v) for v in p.split(",")] for p in s["input"]["seeds_px"].split(";")])
    true = np.array([[float(v) for v in p.split(",")] for p in meta["seeds"].split(";")])
    assert np.abs(found - true).max() < 1.0
    mc = s["monte_carlo"]
    assert mc["draws"] == 4 and mc["mu_high"]["n_defined"] == 4
    assert math.isfinite(s["error_analysis"]["e_mu_max"])
    for name in ("tracks.csv", "kinematics.csv", "summary.json", "beta.png", "kinematics.png"):
        assert (out / name).is_file()
