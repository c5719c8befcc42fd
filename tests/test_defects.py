"""Stuck (hot or dead) sensor pixels: found on the recording's median, replaced, tracked through."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from abu.cli.main import main
from measurement.imaging.defects import correct_defects, find_defects
from measurement.imaging.frames_io import read_recording, write_multipage_tiff
from twin.render import MarkerStyle, RenderSettings, render_markers
from twin.scenario import random_scenario, render_scenario_frames, simulate_scenario


def test_stuck_pixels_are_found_and_nothing_else():
    """A hot and a dead pixel beside a static blurred disk of 2.5 px radius (smaller than any
    marker) and a moving one: exactly the two are found, and replaced by the background; so
    are a pair and a column of three."""
    n = 40
    moving = np.stack([30.0 + 0.8 * np.arange(n), np.full(n, 45.0)], axis=1)
    true = np.stack([np.tile([20.0, 20.0], (n, 1)), moving], axis=1)
    settings = RenderSettings(width=80, height=64, background=60.0, noise_sigma=2.0)
    frames = render_markers(true, [MarkerStyle(2.5, 200.0), MarkerStyle(5.0, 200.0)],
                            settings, 3)
    frames[:, 10, 40] = 255
    frames[:, 58, 10] = 0
    found = find_defects(frames)
    assert sorted(map(tuple, found.tolist())) == [(10, 40), (58, 10)]
    # side by side (a pair, a column of three), each hid the other from a max/min rule
    clustered = frames.copy()
    clustered[:, 30:32, 60] = 255
    clustered[:, 50:53, 30] = 0
    assert sorted(map(tuple, find_defects(clustered).tolist())) == [
        (10, 40), (30, 60), (31, 60), (50, 30), (51, 30), (52, 30), (58, 10)]
    assert np.abs(correct_defects(clustered)[0][:, 30:32, 60].astype(float) - 60.0).max() < 15
    fixed, where = correct_defects(frames)
    assert abs(float(np.mean(fixed[:, 10, 40])) - 60.0) < 5.0
    assert abs(float(np.mean(fixed[:, 58, 10])) - 60.0) < 5.0
    assert np.array_equal(np.delete(fixed.reshape(n, -1), [10 * 80 + 40, 58 * 80 + 10], 1),
                          np.delete(frames.reshape(n, -1), [10 * 80 + 40, 58 * 80 + 10], 1))


@pytest.mark.parametrize("lighting", ["ring", "two_spot", "two_spot_alt"])
def test_no_defect_is_found_on_the_twin_recordings(lighting):
    """The family's recordings have none: their measurement is as it was."""
    scn = random_scenario(20011, lighting=lighting, n_frames=1000)
    frames = render_scenario_frames(scn, *simulate_scenario(scn))
    assert len(find_defects(frames)) == 0
    assert correct_defects(frames)[0] is frames


def test_stuck_pixels_on_the_cd_markers_path_are_measured_through(tmp_path):
    """30 pixels stuck at 255, 12 of them on the CD marker's path: measured, mu covered, the
    pixels named in summary.json. (Without the correction: "marker 'cd' lost in frames 1-3071
    ... cannot interpolate".)"""
    rec, out = tmp_path / "rec", tmp_path / "m"
    assert main(["render", "--scenario", "random", "--seed", "20007", "--out", str(rec),
                 "--quiet"]) == 0
    meta = json.loads((rec / "meta.json").read_text())
    frames = np.array(read_recording(rec / "frames.tif").frames)
    (cx, cy), (px, py) = (np.array(s.split(","), dtype=float)
                          for s in meta["seeds"].split(";")[:2])
    r, a0 = math.hypot(px - cx, py - cy), math.atan2(py - cy, px - cx)
    path = [(round(cy + r * math.sin(a0 + a)), round(cx + r * math.cos(a0 + a)))
            for a in np.linspace(0.1, 2 * math.pi - 0.1, 12)]
    rng = np.random.default_rng(8)
    others = list(zip(rng.integers(2, 254, 18), rng.integers(2, 254, 18)))
    stuck = np.array(path + others)
    frames[:, stuck[:, 0], stuck[:, 1]] = 255
    write_multipage_tiff(rec / "frames.tif", frames, fps_hz=meta["fps"])
    assert main(["measure", str(rec / "frames.tif"), "--out", str(out), "--no-plots",
                 "--quiet", *(["--ball-reflections", "2"] if meta["ball_reflections"] == 2
                              else [])]) == 0
    summary = json.loads((out / "summary.json").read_text())
    found = summary["input"]["defective_pixels"]
    assert found["count"] == len({tuple(p) for p in stuck.tolist()})
    assert {tuple(p) for p in found["first_xy_px"]} == {(c, r) for r, c in stuck.tolist()}
    assert summary["mu_low"] <= meta["mu"] <= summary["mu_high"]
