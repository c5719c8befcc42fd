"""Every figure the commands draw, fit for a paper (issue 20): ``benchmarks/make_figures.py``'s
``make_all`` writes them into a test folder (the measurement from a synthetic tracks CSV
instead of a render), and each is checked:

* PNG at >= 150 dpi (the pHYs chunk read back by Pillow, and the pixel size against the
  figure size); PDF and SVG written when asked;
* the layout (:func:`abu_model.figure_files.layout_problems`): no text cut by the canvas, no
  two texts overlapping, no legend on a panel;
* the histogram's count axis has integer ticks only; the |omega_dot| panel's y limits lie
  within the trusted samples' range (not the edge artefacts'); beta's fit panel is scaled to
  the measured beta inside the fit window; the upper-bound model curve's label names its mu_d.
"""
from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

import abu_model.figure_files as ff

ROOT = Path(__file__).resolve().parents[1]
EXPECTED = {"measure": {"beta", "kinematics"}, "measure-summary": {"histogram"},
            "simulate": {"omega", "omega_dot", "beta", "beta_dot", "mu_req"},
            "design": {"design"}, "next": {"next"}, "identify": {"fit"}}


def _make_figures_module():
    spec = importlib.util.spec_from_file_location("make_figures",
                                                  ROOT / "benchmarks" / "make_figures.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def tracks_csv(tmp_path_factory):
    from synthetic_tracks import measured_pixels, simulate, write_tracks_csv

    record = simulate(0.02, "steps", n=1500)
    x, y = measured_pixels(record, sigma_px=0.02, harmonic_px=0.4, seed=11)
    return write_tracks_csv(tmp_path_factory.mktemp("tracks") / "tracks.csv", record, x, y)


def _capture(monkeypatch) -> dict:
    """Record every figure saved (stem -> [(figure, layout problems)])."""
    import harness.experiments.plots as hp
    import measurement.report.plots as mp

    drawn, original = {}, ff.save_figure

    def capture(fig, path, figure_format="png"):
        # keyed by stem, in order: measure's beta is saved before simulate's
        drawn.setdefault(Path(path).stem, []).append((fig, ff.layout_problems(fig)))
        return original(fig, path, figure_format)

    for module in (ff, hp, mp):
        monkeypatch.setattr(module, "save_figure", capture)
    return drawn


@pytest.fixture(scope="module")
def pngs(tmp_path_factory, fmu_dir, tracks_csv):
    mp = pytest.MonkeyPatch()
    try:
        drawn = _capture(mp)
        out = tmp_path_factory.mktemp("figures")
        fmus = next(iter(fmu_dir.values())).parent
        figures = _make_figures_module().make_all(out, "png", fmu_dir=fmus,
                                                  tracks_csv=tracks_csv, design_check=False)
    finally:
        mp.undo()
    return out, figures, drawn


def test_every_figure_is_written_at_print_resolution(pngs):
    from PIL import Image

    out, figures, drawn = pngs
    for cmd, names in EXPECTED.items():
        assert {p.stem for p in figures[cmd]} == names, cmd
        for path in figures[cmd]:
            with Image.open(path) as img:
                dpi = img.info["dpi"]
                width_px = img.size[0]
            assert min(dpi) >= 150 - 0.5, (path, dpi)
            widths = [fig.get_figwidth() for fig, _ in drawn[path.stem]]
            assert width_px >= 150 * min(widths) - 2 and min(widths) >= 6.0, (path, width_px)
    print(f"\nfigures in {out}")


def test_no_clipped_or_overlapping_text_and_legends_off_the_data(pngs):
    _, _, drawn = pngs
    problems = {name: p for name, figs in drawn.items() for _, p in figs if p}
    assert not problems


def test_histogram_counts_are_integers_and_the_median_is_an_interval(pngs):
    _, _, drawn = pngs
    ax = drawn["histogram"][0][0].axes[0]
    lo, hi = ax.get_ylim()
    ticks = [v for v in ax.get_yticks() if lo <= v <= hi]
    assert ticks and all(float(v).is_integer() for v in ticks), ticks
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert any(s.startswith("Turnbull median in [") for s in labels), labels


def test_axes_are_scaled_to_the_trusted_data(pngs):
    out, _, drawn = pngs
    table = np.genfromtxt(out / "measure" / "kinematics.csv", delimiter=",", names=True)
    summary = json.loads((out / "measure" / "summary.json").read_text())
    trusted = table["trusted"] == 1
    k = summary["slip_detection"]["k_sigma"]
    a = np.abs(table["omega_dot_rad_s2"])
    band = k * table["sigma_omega_dot_rad_s2"] + table["bias_omega_dot_rad_s2"]
    lo, hi = float(np.min((a - band)[trusted])), float(np.max((a + band)[trusted]))
    span = hi - min(lo, 0.0)
    ax = drawn["kinematics"][0][0].axes[1]
    y0, y1 = ax.get_ylim()
    assert min(lo, 0.0) - 0.1 * span <= y0 and y1 <= hi + 0.1 * span, ((y0, y1), (lo, hi))
    # the untrusted edges hold values outside: they do not set the scale
    everything = np.concatenate([a - band, a + band])
    assert np.nanmax(everything) > y1 or np.nanmin(everything) < y0
    # beta: panel (a) spans the measured beta in the fit window, not the post-slip motion
    fitted = np.isfinite(table["beta_model_rad"])
    beta = table["beta_clean_rad"][fitted]
    fig = drawn["beta"][0][0]
    b0, b1 = fig.axes[0].get_ylim()
    pad = 0.2 * float(np.ptp(beta))
    assert beta.min() - pad <= b0 <= beta.min() and beta.max() <= b1 <= beta.max() + pad
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    high = summary["model_fit"]["model_curves"]["high"]
    assert any(f"mu_d = {high['mu_d']:.3g}" in s and "highest mu" in s for s in labels), labels


def test_each_interval_is_one_legend_entry_with_its_numbers(pngs):
    """Panel (c) of the kinematics figure: each interval (the model fit's, the running max's)
    is one legend entry that shows both bound lines and states [low, high] as summary.json."""
    out, _, drawn = pngs
    summary = json.loads((out / "measure" / "summary.json").read_text())
    legend = drawn["kinematics"][0][0].axes[2].get_legend()
    labels = [t.get_text() for t in legend.get_texts()]
    rm = summary["running_max"]
    expected = [f"model fit, {100 * summary['confidence']:g} %: "
                f"[{summary['mu_low']:.4g}, {summary['mu_high']:.4g}]",
                f"running max: [{rm['mu_low']:.4g}, {rm['mu_high']:.4g}]"]
    assert all(e in labels for e in expected), labels
    from matplotlib.colors import to_hex

    from matplotlib.lines import Line2D

    drawn_lines = {(line.get_linestyle(), to_hex(line.get_color()))
                   for line in legend.findobj(Line2D)}
    for style in ("--", ":"):   # each interval's low (green) and high (red) line
        assert {(style, to_hex("C2")), (style, to_hex("C3"))} <= drawn_lines, drawn_lines


def test_pdf_and_svg_on_request(tmp_path, tracks_csv, fmu_dir):
    from abu.cli.main import main

    assert main(["measure", str(tracks_csv), "--tracks", "--out", str(tmp_path / "m"),
                 "--figure-format", "pdf", "--quiet", "--mc-draws", "0"]) == 0
    for name in ("beta.pdf", "kinematics.pdf"):
        assert (tmp_path / "m" / name).read_bytes()[:5] == b"%PDF-"
    assert not list((tmp_path / "m").glob("*.png"))
    assert main(["measure-summary", str(tmp_path / "m" / "summary.json"), "--out",
                 str(tmp_path / "s"), "--figure-format", "svg"]) == 0
    assert b"<svg" in (tmp_path / "s" / "histogram.svg").read_bytes()[:500]
    assert main(["design", "--mu-range", "0.02", "0.04", "--no-check", "--out",
                 str(tmp_path / "d"), "--figure-format", "svg"]) == 0
    assert (tmp_path / "d" / "design.svg").is_file()
    fmus = str(next(iter(fmu_dir.values())).parent)
    assert main(["simulate", "--out", str(tmp_path / "sim"), "--fmu-dir", fmus,
                 "--figure-format", "pdf"]) == 0
    assert sorted(p.name for p in (tmp_path / "sim").glob("*.pdf")) == [
        "beta.pdf", "beta_dot.pdf", "mu_req.pdf", "omega.pdf", "omega_dot.pdf"]
    # the same data give the same bytes (no creation date in the file)
    assert main(["measure-summary", str(tmp_path / "m" / "summary.json"), "--out",
                 str(tmp_path / "s2"), "--figure-format", "svg"]) == 0
    assert (tmp_path / "s2" / "histogram.svg").read_bytes() == \
        (tmp_path / "s" / "histogram.svg").read_bytes()


@pytest.mark.parametrize("facecolor", ["white", (1.0, 1.0, 1.0, 0.0)])
def test_png_holds_the_pixels_savefig_draws(tmp_path, facecolor):
    """The PNG writer of :func:`abu_model.figure_files.save_figure` (unfiltered rows, zlib
    level 1) stores the very pixels matplotlib's own PNG (Pillow) does, at PNG_DPI with the
    settings of DRAW_RC, RGB for an opaque figure and RGBA for a transparent one; Pillow reads it
    back with its dpi."""
    import io

    import matplotlib

    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from PIL import Image

    fig = Figure(figsize=(3.1, 2.2), facecolor=facecolor)
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    ax.plot(np.linspace(0, 1, 50), np.sin(np.linspace(0, 9, 50)), label="a curve")
    ax.legend()
    ax.set_xlabel("time [s]")
    reference = io.BytesIO()
    with matplotlib.rc_context(ff.DRAW_RC):
        fig.savefig(reference, format="png", dpi=ff.PNG_DPI)
    path = ff.save_figure(fig, tmp_path / "f", "png")
    assert path.name == "f.png" and fig.dpi == 100     # the figure's own dpi is restored
    with Image.open(path) as mine, Image.open(reference) as ref:
        mine.load()
        assert mine.mode == ("RGB" if facecolor == "white" else "RGBA")
        assert mine.size == ref.size == (round(3.1 * ff.PNG_DPI), round(2.2 * ff.PNG_DPI))
        assert min(mine.info["dpi"]) >= ff.PNG_DPI - 0.5
        assert np.array_equal(np.asarray(mine.convert("RGBA")), np.asarray(ref.convert("RGBA")))
