"""The tracker's compiled kernels (``measurement.imaging._trackc``) against its NumPy/OpenCV
path on the same frames: the seeded pass identical, the isocontour refinement (contour fit and
edge step) within 1e-9 px, every lost-marker reason identical.

The frames cover each branch of the kernels: three markers turning at -19 Hz, dark markers,
a lighting gradient, a removed marker (low contrast), a jump, a second blob, a marker leaving
the image, odd and even windows, smoothing on and off, a non-contiguous frame stack.
"""
from __future__ import annotations

import numpy as np
import pytest

from measurement.imaging import edge_step as E
from measurement.imaging import track_passes as P
from measurement.imaging.tracking import TrackingOptions, track_recording
from twin.render import CameraGeometry, MarkerStyle, RenderSettings, render_frames, render_markers

TOL_PX = 1e-9
KERNEL = P._trackc
STEP = TrackingOptions(edge_step=True)  # the kernels' every branch: the optional edge step too


def test_the_kernel_is_built():
    assert KERNEL is not None, ("measurement.imaging._trackc is not built: run `pip install -e .` "
                                "(or `python setup.py build_ext --inplace`) with a C compiler")


def both_paths(monkeypatch, frames, seeds, **kw):
    monkeypatch.setattr(P, "_trackc", KERNEL)
    fast = track_recording(frames, seeds, **kw)
    monkeypatch.setattr(P, "_trackc", None)
    slow = track_recording(frames, seeds, **kw)
    monkeypatch.setattr(P, "_trackc", KERNEL)
    return fast, slow


def assert_same(fast, slow):
    np.testing.assert_array_equal(fast.reason, slow.reason)
    np.testing.assert_array_equal(fast.lost, slow.lost)
    for name in ("x", "y", "radius"):
        a, b = getattr(fast, name), getattr(slow, name)
        np.testing.assert_array_equal(np.isnan(a), np.isnan(b))
        ok = ~np.isnan(a)
        assert np.max(np.abs(a[ok] - b[ok]), initial=0.0) <= TOL_PX, name


def rotating(n=240, seed=11, **settings_kw):
    fps = 4500.0
    t = np.arange(n) / fps
    theta = 0.4 - 2 * np.pi * 19.0 * t
    beta = 1.2 + 0.3 * t
    c, p, b = CameraGeometry().marker_positions(theta, beta)
    settings = RenderSettings(noise_sigma=3.0, exposure_fraction=0.25, **settings_kw)
    frames = render_frames(c, p, b, settings, seed=seed)
    return frames, np.stack([c[0], p[0], b[0]]) + 0.6, settings


@pytest.mark.skipif(KERNEL is None, reason="compiled kernel not built (test_the_kernel_is_built)")
class TestSamePositions:
    def test_seeded_pass_is_identical(self):
        frames, seeds, _ = rotating()
        frames[50, 100:140, :] = 60   # a marker hidden for a frame: low contrast, re-acquired
        opts = TrackingOptions()
        for dark in (False, True):
            f = 255 - frames if dark else frames
            fast = P.seeded_moments(f, seeds, 30, dark, opts)
            P._trackc = None
            try:
                slow = P.seeded_moments(f, seeds, 30, dark, opts)
            finally:
                P._trackc = KERNEL
            for a, b in zip(fast, slow):
                np.testing.assert_array_equal(a, b)

    @pytest.mark.parametrize("kw", [{}, {"window": 21}, {"window": 36},
                                    {"options": TrackingOptions(smooth=False)},
                                    {"options": TrackingOptions(edge_step=True)},
                                    {"options": TrackingOptions(edge_step=True,
                                                                edge_width_px=0.1)},
                                    {"options": TrackingOptions(min_snr=30.0)}])
    def test_rotating_recording(self, monkeypatch, kw):
        frames, seeds, _ = rotating()
        fast, slow = both_paths(monkeypatch, frames, seeds, **kw)
        assert_same(fast, slow)
        assert fast.lost.mean() < 0.9

    def test_dark_markers_and_gradient(self, monkeypatch):
        frames, seeds, _ = rotating(n=120, seed=3, gradient=0.5, background=200.0,
                                    centre=MarkerStyle(6.0, 60.0), cd=MarkerStyle(4.5, 70.0),
                                    ball=MarkerStyle(5.0, 50.0))
        fast, slow = both_paths(monkeypatch, frames, seeds, dark=True, options=STEP)
        assert_same(fast, slow)
        assert not fast.lost.any()

    def test_every_lost_reason(self, monkeypatch):
        frames, seeds, _ = rotating(n=200, seed=5)
        frames[40] = 60                                 # all markers gone: low contrast
        frames[80] = np.roll(frames[80], 9, axis=1)     # a jump
        frames[120, 118:134, 118:134] = 230             # a bright patch beside the centre
        fast, slow = both_paths(monkeypatch, frames, seeds, options=STEP)
        assert_same(fast, slow)
        assert len(set(fast.reason.ravel().tolist())) >= 3, fast.lost_summary()

    def test_marker_leaving_the_image_and_non_contiguous_frames(self, monkeypatch):
        true = np.stack([np.linspace(22.0, 6.0, 17), np.full(17, 32.0)], axis=1)[:, None, :]
        frames = render_markers(true, [MarkerStyle(5.0, 180.0)],
                                RenderSettings(width=64, height=64, background=60.0), 8)
        wide = np.zeros((17, 64, 128), np.uint8)
        wide[:, :, ::2] = frames
        view = wide[:, :, ::2]                          # strided: not C-contiguous
        fast, slow = both_paths(monkeypatch, view, true[0])
        assert_same(fast, slow)
        assert fast.lost.any() and not fast.lost.all()
        assert_same(fast, track_recording(frames, true[0]))


@pytest.mark.skipif(KERNEL is None, reason="compiled kernel not built (test_the_kernel_is_built)")
def test_short_buffers_are_refused():
    frames = np.zeros((2, 40, 40), np.uint8)
    out = np.empty((2, 1))
    with pytest.raises(ValueError, match="frames"):
        KERNEL.seeded(frames, 3, 40, 40, 1, 30, False, 12.0, 10.0, np.zeros(4), out, out,
                      np.zeros((2, 1), np.uint8))
    idx = np.zeros(1, np.int64)
    with pytest.raises(ValueError, match="outside the frames"):
        KERNEL.refine(frames, 2, 40, 40, idx, idx + 20, idx, 1, 30, False, idx, np.zeros(3),
                      True, 12.0, 6.0, 1.0, 13.0, 0.6, 8.0, True, 0.4, E.BAND_PX,
                      E.MAX_STEP_PX, E.TABLE_HALF, E.PHI, E.DPHI, np.empty(1), np.empty(1),
                      np.empty(1), np.empty(1, np.uint8))
