"""Where the tracker's edge step (``measurement/imaging/edge_step.py``) applies by default.

The command line's tracker (``reflections.track_markers``, what ``abu track`` / ``abu measure``
run) ends the contour fit with the step on the centre and CD paper disks of a one-reflection
recording, with the RMS error against the rendered truth lower on each, and never on the ball:
its image is a highlight, where the step's uniform-disk model raises the frame-to-frame noise
(shown here on the harsh twin), or with two reflections its outline (never stepped, even when
``--edge-step`` asks for it); with two reflections the paper markers are not stepped either
(:func:`measurement.imaging.edge_step_roles.edge_step_default`). ``--no-edge-step`` turns it
off; ``tracking.json`` states what was used.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

from abu.cli.main import main
from measurement.imaging.frames_io import write_npy
from measurement.imaging.markers import format_seeds
from measurement.imaging.reflections import track_markers
from measurement.imaging.tracking import TrackingOptions, track_recording
from twin.render import CameraGeometry, RenderSettings, render_frames

ROLES = ("centre", "CD", "ball")


def _three_disks(n: int = 600, seed: int = 4):
    """The bench's three markers (radii 6, 4.5, 5 px, noise 3) turning at -9 .. -19 Hz."""
    t = np.arange(n) / 4500.0
    theta = 0.3 - 2 * np.pi * (9.0 * t + 20.0 * t * t)
    beta = 1.0 + 0.4 * t
    c, p, b = CameraGeometry().marker_positions(theta, beta)
    settings = RenderSettings(noise_sigma=3.0, exposure_fraction=0.25)
    frames = render_frames(c, p, b, settings, seed=seed)
    return frames, np.stack([c, p, b + settings.ball_shift_vector], axis=1)


def _rms(tracks, truth) -> np.ndarray:
    e2 = (tracks.x - truth[:, :, 0]) ** 2 + (tracks.y - truth[:, :, 1]) ** 2
    return np.sqrt(np.nanmean(e2, axis=0))


def _same(a, b, cols=slice(None)) -> bool:
    return all(np.array_equal(getattr(a, k)[:, cols], getattr(b, k)[:, cols], equal_nan=True)
               for k in ("x", "y", "lost", "reason"))


def test_the_default_steps_the_paper_disks_and_not_the_ball():
    frames, truth = _three_disks()
    seeds = truth[0]
    on = track_recording(frames, seeds, options=TrackingOptions(edge_step=True))
    off = track_recording(frames, seeds, options=TrackingOptions(edge_step=False))
    default = track_markers(frames, seeds)
    assert default.stepped() == (True, True, False)
    assert _same(default, on, slice(0, 2)) and _same(default, off, 2)
    assert _same(track_markers(frames, seeds, edge_step=False), off)
    assert _same(track_markers(frames, seeds, edge_step=True), on)
    rms_on, rms_off = _rms(on, truth), _rms(off, truth)
    print(f"\nthree disks, 600 frames, noise 3: RMS error [px] (centre, CD, ball) contour alone "
          f"{np.round(rms_off, 4)}, with the edge step {np.round(rms_on, 4)}, default "
          f"{np.round(_rms(default, truth), 4)}")
    assert not on.lost.any()
    for m in (0, 1):
        assert np.nanmax(np.abs(on.x[:, m] - off.x[:, m])) > 1e-3, ROLES[m]  # it moved it
        assert rms_on[m] < 0.95 * rms_off[m], (ROLES[m], rms_on, rms_off)     # and it paid


def _white(x: np.ndarray) -> float:
    """Frame-to-frame noise [px]: second differences remove the smooth motion."""
    d2 = x[2:] - 2 * x[1:-1] + x[:-2]
    return float(np.sqrt(np.nanmean(d2 * d2) / 6))


def _harsh(seed: int, lighting: str, n: int = 600):
    from twin.scenario import random_scenario, render_scenario_frames, simulate_scenario

    scn = random_scenario(seed, size=200, lighting=lighting).with_(n_frames=1000)
    st, pos = simulate_scenario(scn)
    frames = render_scenario_frames(scn, st, pos)[:n]
    return frames, np.stack([pos["centre"][0], pos["cd"][0], pos["ball"][0]])


def test_the_step_does_not_suit_the_balls_highlight():
    """The harsh twin's TL-ring highlight is no uniform disk: the step raises its frame-to-frame
    noise (seeds 1001-1013 at 256 px: 0.039 -> 0.056 px, medians, higher in 10 of 10)."""
    frames, seeds = _harsh(1007, "ring")
    on = track_recording(frames, seeds, options=TrackingOptions(edge_step=True))
    off = track_recording(frames, seeds, options=TrackingOptions(edge_step=False))
    noise = [(_white(off.x[:, m]) + _white(off.y[:, m]), _white(on.x[:, m]) + _white(on.y[:, m]))
             for m in range(3)]
    print(f"\nharsh twin seed 1007 (ring), 600 frames: frame-to-frame noise [px] (contour alone, "
          f"with the step) {np.round(noise, 4).tolist()}")
    assert not on.lost.any() and not off.lost.any()
    assert noise[2][1] > 1.1 * noise[2][0]


@pytest.fixture(scope="module")
def two_spot():
    """300 frames of the harsh twin under the two-spot lighting (two highlights on the ball)."""
    return _harsh(12, "two_spot", n=300)


def test_the_default_never_steps_the_two_reflection_ball(two_spot):
    frames, seeds = two_spot
    default = track_markers(frames, seeds, ball_reflections=2)
    off = track_markers(frames, seeds, ball_reflections=2, edge_step=False)
    on = track_markers(frames, seeds, ball_reflections=2, edge_step=True)
    assert default.stepped() == (False, False, False) and _same(default, off)
    # forced on, the step moves the centre and CD disks but never the ball's outline
    assert on.stepped() == (True, True, False)
    assert _same(on, off, 2) and not default.lost[:, 2].any()
    for m in (0, 1):
        assert np.nanmax(np.abs(on.x[:, m] - off.x[:, m])) > 1e-3, ROLES[m]


def test_the_command_line_states_and_switches_the_step(tmp_path, two_spot):
    frames, _ = _three_disks(n=64)
    path = write_npy(tmp_path / "rec.npy", frames)
    two = write_npy(tmp_path / "two.npy", two_spot[0][:64])

    def used(name: str, rec, *extra: str):
        out = tmp_path / name
        assert main(["track", str(rec), "--out", str(out), "--fps", "4500", "--quiet",
                     *extra]) == 0
        info = json.loads((out / "tracking.json").read_text())
        return info["edge_step"], info["edge_step_markers"]

    assert used("default", path) == (True, ["center", "cd"])
    assert used("off", path, "--no-edge-step") == (False, [])
    assert used("on", path, "--edge-step") == (True, ["center", "cd", "ball"])
    seeds = format_seeds(two_spot[1])
    assert used("two", two, "--ball-reflections", "2", "--seeds", seeds) == (False, [])
    assert used("two_on", two, "--ball-reflections", "2", "--seeds", seeds,
                "--edge-step") == (True, ["center", "cd"])
    with pytest.raises(SystemExit) as exc:   # both at once: argparse's usage error
        main(["track", str(path), "--out", str(tmp_path / "both"), "--fps", "4500",
              "--edge-step", "--no-edge-step"])
    assert exc.value.code == 2 and not (tmp_path / "both").exists()
