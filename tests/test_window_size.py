"""The tracking window sized from the markers (``--window`` not given): recordings of a camera
2x closer and 2x farther than the family's are measured with the default options, the window
follows the markers' geometry, and markers that leave no window are refused with the numbers."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from abu.cli.main import main
from measurement.imaging.window_size import FAMILY_WINDOW_PX, WindowError, choose_window
from twin.render import CameraGeometry, MarkerStyle, RenderSettings, render_frames


def _rendered(tmp_path_factory, seed: int, zoom: float, size: int):
    """A 1000-frame recording of ``twin.scenario.random_scenario(seed)`` seen at ``zoom`` times
    the family's magnification (TIFF with its frame rate) and its true mu."""
    import tifffile

    from measurement.imaging.frame_rate import tiff_metadata
    from twin.scenario import magnified, random_scenario, render_scenario_frames, \
        simulate_scenario

    scn = magnified(random_scenario(seed, size=size, n_frames=1000), zoom)
    assert scn.lighting.reflections == 1          # measured with the default options
    state, pos = simulate_scenario(scn)
    path = tmp_path_factory.mktemp(f"zoom{zoom}") / "frames.tif"
    tifffile.imwrite(path, render_scenario_frames(scn, state, pos), photometric="minisblack",
                     contiguous=True, metadata=tiff_metadata(scn.fps, 0.0))
    return path, scn


@pytest.fixture(scope="module")
def closer(tmp_path_factory):
    """2x the family's magnification (0.15 mm/px, 512 px): centre marker ~13 px in radius.
    With the former fixed 30 px window: "marker 'center' lost ...; most lost windows cut a
    blob at their edge" (asserted below)."""
    return _rendered(tmp_path_factory, 20101, 2.0, 512)


@pytest.fixture(scope="module")
def farther(tmp_path_factory):
    """0.5x (0.6 mm/px): the ball passes ~19 px from the centre marker, inside a 30 px window."""
    return _rendered(tmp_path_factory, 20000, 0.5, 256)


def _measure(path, out, *args) -> tuple[int, dict | None]:
    code = main(["measure", str(path), "--out", str(out), "--no-plots", "--quiet", *args])
    summary = out / "summary.json"
    return code, json.loads(summary.read_text()) if code == 0 else None


@pytest.mark.parametrize("case", ["closer", "farther"])
def test_other_magnifications_are_measured_with_the_default_options(case, request, tmp_path):
    path, scn = request.getfixturevalue(case)
    code, s = _measure(path, tmp_path / "auto")
    assert code == 0
    mu = scn.ball.mu
    print(f"{case}: window {s['input']['window_px']} px, mu {mu:.5f} in "
          f"[{s['mu_low']}, {s['mu_high']}]")
    assert s["mu_low"] is not None and s["mu_high"] is not None
    assert s["mu_low"] <= mu <= s["mu_high"]
    choice = s["input"]["window_choice"]               # recorded where it is not 30 px
    assert choice["window_px"] == s["input"]["window_px"]
    assert choice["needs_px"] <= choice["window_px"] <= choice["allows_px"]
    l_px = scn.ball.l / scn.pixel_size
    assert choice["ball_path_radius_px"] == pytest.approx(l_px, abs=1.0)
    if case == "closer":   # the window holds the centre marker's disk and the 2 px ring
        assert (choice["window_px"] / 2 - 2.5) > scn.centre_radius_px + 1.0
    else:                  # its corner stays short of the ball's path
        assert math.sqrt(2) * choice["window_px"] / 2 < l_px - scn.ball_radius_px
    # the fixed 30 px window of before (an explicit --window still wins) loses a marker
    assert _measure(path, tmp_path / "w30", "--window", "30")[0] == 2


def _frames(zoom: float, radii: tuple[float, float, float], n: int = 6,
            step_rad: float = 0.012) -> tuple[np.ndarray, np.ndarray, CameraGeometry]:
    """Frames of three disks (centre, CD, ball radii [px]) seen at ``zoom`` times 0.3 mm/px,
    the CD turning ``step_rad`` a frame; the seeds (3, 2) [px] of frame 0."""
    size = 512 if zoom > 1 else 256
    geo = CameraGeometry(pixel_size=0.3e-3 / zoom, centre_x=size / 2 + 0.3,
                         centre_y=size / 2 - 0.4)
    theta = 0.4 - step_rad * np.arange(n)
    c, p, b = geo.marker_positions(theta, np.full(n, 1.2))
    settings = RenderSettings(width=size, height=size, centre=MarkerStyle(radii[0], 200.0),
                              cd=MarkerStyle(radii[1], 190.0), ball=MarkerStyle(radii[2], 215.0))
    return render_frames(c, p, b, settings, seed=3), np.stack([c[0], p[0], b[0]]), geo


@pytest.mark.parametrize("zoom, radii", [(1.0, (7.0, 5.5, 5.0)), (1.0, (5.0, 4.0, 5.0)),
                                         (2.0, (14.0, 11.0, 10.0)), (1.5, (10.0, 8.0, 7.5)),
                                         (0.5, (3.5, 2.8, 2.5)), (0.6, (4.2, 3.3, 3.0))])
def test_the_window_follows_the_markers_geometry(zoom, radii):
    """Against the true radii and distances: the window holds the largest disk, its 2 px
    border ring and the frame-to-frame motion twice (each side), and its corner never
    reaches another marker's disk; the family's markers (radius <= 7 px at 0.3 mm/px) keep
    exactly 30 px."""
    frames, seeds, geo = _frames(zoom, radii)
    w = choose_window(frames, seeds).window_px
    step_cd = geo.r_cd_px * 0.012                        # px a frame
    assert w / 2 - 2.5 >= max(radii[0], radii[2], radii[1] + 2 * step_cd)
    l_px = geo.l_px
    assert math.sqrt(2) * w / 2 <= l_px - max(radii[0], radii[2])
    assert math.sqrt(2) * w / 2 <= geo.r_cd_px - l_px - max(radii[1], radii[2])
    if zoom == 1.0:
        assert w == FAMILY_WINDOW_PX
    elif zoom > 1:
        assert w > FAMILY_WINDOW_PX
    else:
        assert w < FAMILY_WINDOW_PX


def test_markers_that_leave_no_window_are_refused_with_the_numbers(tmp_path):
    """A centre marker of 9 px radius with the ball's path 19 px away: the window that holds
    it (>= 25 px) reaches the ball (<= 12 px). One line names the marker, both sizes and
    --window (exit status 2, nothing written); an explicit --window is tracked with."""
    from measurement.imaging.tracks_io import LostMarkerError
    from measurement.pipeline import TrackingSettings, track_recording

    frames, seeds, _ = _frames(0.5, (9.0, 3.0, 4.0), n=40)
    path = tmp_path / "frames.npy"
    np.save(path, frames)
    with pytest.raises(WindowError) as err:
        track_recording(path, fps_hz=4500.0, settings=TrackingSettings(seeds_px=seeds))
    text = str(err.value)
    print(text)
    assert "\n" not in text and "frames.npy" in text
    assert "no tracking window fits" in text and "centre marker" in text
    assert "--window" in text
    needs = float(text.split("needs >= ")[1].split(" px")[0])
    allows = float(text.split("allows <= ")[1].split(" px")[0])
    assert needs >= 2 * (9.0 + 2.5) and allows <= math.sqrt(2) * (19.2 - 4.0) and needs > allows
    with pytest.raises(WindowError):
        choose_window(frames, seeds)
    with pytest.raises(LostMarkerError, match="inside --window 40 px"):   # tracked with it
        track_recording(path, fps_hz=4500.0,
                        settings=TrackingSettings(seeds_px=seeds, window_px=40))
    code = main(["track", str(path), "--fps", "4500", "--out", str(tmp_path / "t"), "--quiet",
                 "--seeds", ";".join(f"{x:.2f},{y:.2f}" for x, y in seeds)])
    assert code == 2 and not (tmp_path / "t").exists()


def test_a_fast_marker_near_the_ball_gets_the_one_step_room():
    """A designed braking run at 40 Hz (bench_profile_drive seed 207): the CD marker of 6.8 px
    outer radius moves 5 px a frame, the ball passes 36.1 px from the centre and 52.6 px from
    the CD marker. Two steps of room want 38.5 px, the distances allow 38.9 (no whole window);
    one step (the tracker predicts the motion from frame 2 on) wants 28.6: a window is chosen,
    not a refusal (the family's 30 px tracked it)."""
    from measurement.imaging.window_size import MarkerExtent, hold_px, window_from_extents
    seeds = np.array([[128.67, 127.04], [217.34, 126.99], [128.32, 90.96]])
    extents = [MarkerExtent(6.0, 0.1, 100.0), MarkerExtent(6.8, 5.0, 100.0),
               MarkerExtent(4.5, 5.0, 100.0)]
    assert hold_px(extents[1]) > 38.0 and hold_px(extents[1], 1.0) < 30.0
    choice = window_from_extents(seeds, extents, 256)
    assert hold_px(extents[1], 1.0) <= choice.window_px <= choice.allows_px
    # a static marker too large for its gap is still refused (one step of nothing is nothing)
    with pytest.raises(WindowError):
        window_from_extents(seeds, [MarkerExtent(20.0, 0.0, 100.0), *extents[1:]], 256)


def test_markers_too_faint_to_measure_and_too_close_are_refused_not_crashed():
    """No marker measurable (all too faint) and seeds closer than the least window allows:
    a WindowError with the numbers (it was a TypeError formatting the missing radius)."""
    from measurement.imaging.window_size import MarkerExtent, window_from_extents
    faint = [MarkerExtent(None, 0.0, 0.0)] * 3
    with pytest.raises(WindowError, match="no marker could be measured"):
        window_from_extents(np.array([[100.0, 100.0], [104.0, 100.0], [102.0, 100.0]]), faint)
