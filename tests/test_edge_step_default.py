"""Where the tracker's edge step (``measurement/imaging/edge_step.py``) applies by default.

On: every marker the ``isocontour`` method measures in a one-reflection recording (the ABU
centre and CD paper disks, the ball's single highlight), with the RMS error against the
rendered truth lower on each. Off: the ball under two reflections (measured by its outline,
never by the step, even when ``--edge-step`` asks for it) and, by
:func:`measurement.imaging.reflections.edge_step_default`, the other markers of such a
recording. ``--no-edge-step`` turns it off; ``tracking.json`` states what was used.
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
               for k in ("x", "y", "lost"))


def test_the_default_steps_every_single_disk_marker():
    frames, truth = _three_disks()
    seeds = truth[0]
    on = track_recording(frames, seeds, options=TrackingOptions(edge_step=True))
    off = track_recording(frames, seeds, options=TrackingOptions(edge_step=False))
    # the library's default and the command line's tracker (one reflection) are the step's
    assert _same(track_recording(frames, seeds), on)
    assert _same(track_markers(frames, seeds), on)
    assert _same(track_markers(frames, seeds, edge_step=False), off)
    rms_on, rms_off = _rms(on, truth), _rms(off, truth)
    print(f"\nthree disks, 600 frames, noise 3: RMS error [px] (centre, CD, ball) without the "
          f"edge step {np.round(rms_off, 4)}, default (with it) {np.round(rms_on, 4)}")
    assert not on.lost.any()
    for m, role in enumerate(ROLES):
        assert np.nanmax(np.abs(on.x[:, m] - off.x[:, m])) > 1e-3, role  # it moved the marker
        assert rms_on[m] < 0.95 * rms_off[m], (role, rms_on, rms_off)    # and it paid


@pytest.fixture(scope="module")
def two_spot():
    """300 frames of the harsh twin under the two-spot lighting (two highlights on the ball)."""
    from twin.scenario import random_scenario, render_scenario_frames, simulate_scenario

    scn = random_scenario(12, size=200, lighting="two_spot").with_(n_frames=1000)
    st, pos = simulate_scenario(scn)
    frames = render_scenario_frames(scn, st, pos)[:300]
    return frames, np.stack([pos["centre"][0], pos["cd"][0], pos["ball"][0]])


def test_the_default_never_steps_the_two_reflection_ball(two_spot):
    frames, seeds = two_spot
    default = track_markers(frames, seeds, ball_reflections=2)
    off = track_markers(frames, seeds, ball_reflections=2, edge_step=False)
    on = track_markers(frames, seeds, ball_reflections=2, edge_step=True)
    assert not default.options.edge_step and _same(default, off)
    # forced on, the step moves the centre and CD disks but never the ball's outline
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
        return json.loads((out / "tracking.json").read_text())["edge_step"]

    assert used("default", path) is True
    assert used("off", path, "--no-edge-step") is False
    seeds = format_seeds(two_spot[1])
    assert used("two", two, "--ball-reflections", "2", "--seeds", seeds) is False
    assert used("two_on", two, "--ball-reflections", "2", "--seeds", seeds,
                "--edge-step") is True
    with pytest.raises(SystemExit) as exc:   # both at once: argparse's usage error
        main(["track", str(path), "--out", str(tmp_path / "both"), "--fps", "4500",
              "--edge-step", "--no-edge-step"])
    assert exc.value.code == 2 and not (tmp_path / "both").exists()
