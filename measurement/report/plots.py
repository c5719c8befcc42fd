"""Figures of one analysed record, fit for a paper (report figs. 5.6-5.9 redrawn; matplotlib is
imported only here, and only when plotting):

* ``beta`` -- the model fit (report fig. 5.6 made quantitative): (a) the fit window, scaled to
  the measured beta inside it (the post-slip motion runs off the top, it does not set the
  scale); (b) the same around the slip, where mu is decided; (c) the residual (measured - best
  model) in mrad. Every model curve's label gives the (mu, mu_d) it was integrated with
  (``summary["model_fit"]["model_curves"]``).
* ``kinematics`` -- |omega| (fig. 5.7), |omega_dot| with its noise + truncation band
  (fig. 5.8), and mu_req(t) with the running maxima of the report's interval and both intervals'
  bounds (fig. 5.9). Every panel's y axis is scaled to the *trusted* samples: the edge artefacts
  of the derivative estimators (greyed, "untrusted") run off the axes instead of flattening
  the data.

Legends sit outside the data (right of the panels, or below them); the layout is constrained
so that no label is clipped. Files: PNG at :data:`abu_model.figure_files.PNG_DPI` dpi, or PDF /
SVG (``figure_format``).
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
# The object-oriented API on the Agg canvas: no pyplot (its import and state machine cost
# ~0.3 s of the 2 s budget of `abu measure`).
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.legend_handler import HandlerTuple
from matplotlib.ticker import MaxNLocator

from abu_model.figure_files import save_figure

FIGURES = ("beta", "kinematics")
#: Font sizes [pt] at the figure's size (7.5-8 in wide: >= 7 pt printed at 6.5 in).
FONT_PT = 9.0
LEGEND_PT = 8.0
UNTRUSTED_GREY = "0.88"
#: At most this many tick intervals on the x and y axes of a panel (round steps): a printed
#: 2-in panel reads well with 4-6 labels, and every tick is a set of artists matplotlib builds
#: and draws (its automatic 7-9 cost 40 ms of the two figures' 0.27 s).
X_TICKS, Y_TICKS = 6, 5
_STEPS = (1, 2, 2.5, 5, 10)


def _figure(width_in: float, height_in: float, *, left_in: float, right_in: float,
            top_in: float, bottom_in: float, hspace: float) -> Figure:
    """A figure with fixed margins [in] (a layout engine costs ~0.25 s a figure; the tests
    check that no text leaves the canvas or overlaps a panel)."""
    fig = Figure(figsize=(width_in, height_in))
    FigureCanvasAgg(fig)
    fig.subplots_adjust(left=left_in / width_in, right=1.0 - right_in / width_in,
                        top=1.0 - top_in / height_in, bottom=bottom_in / height_in,
                        hspace=hspace)
    return fig


def _style(ax, ylabel: str) -> None:
    ax.set_ylabel(ylabel, fontsize=FONT_PT)
    ax.tick_params(labelsize=FONT_PT - 0.5)
    ax.xaxis.set_major_locator(MaxNLocator(X_TICKS, steps=_STEPS))
    ax.yaxis.set_major_locator(MaxNLocator(Y_TICKS, steps=_STEPS))
    ax.grid(True, color="0.92", linewidth=0.6)


def _legend_right(ax, pairs: list[tuple[tuple, str]] = ()) -> None:
    """The panel's legend right of it: its labelled artists, then ``pairs`` of (artists shown
    side by side, label) -- a low and a high bound read as one interval."""
    handles, labels = ax.get_legend_handles_labels()
    for artists, label in pairs:
        handles.append(artists)
        labels.append(label)
    ax.legend(handles, labels, handler_map={tuple: HandlerTuple(ndivide=None, pad=0.8)},
              handlelength=3.2 if pairs else 2.0, loc="upper left", bbox_to_anchor=(1.01, 1.0),
              fontsize=LEGEND_PT, frameon=False, borderaxespad=0.0)


def _limits(values, pad: float = 0.08, floor: float | None = None) -> tuple[float, float] | None:
    """(low, high) of the finite ``values`` with ``pad`` of their range around; None if none."""
    v = np.asarray(values, float)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return None
    lo, hi = float(v.min()), float(v.max())
    if floor is not None:
        lo = min(lo, floor)
    span = hi - lo if hi > lo else max(abs(hi), 1e-12)
    return lo - pad * span, hi + pad * span


def _shade_untrusted(ax, t: np.ndarray, trusted: np.ndarray, label: bool = False) -> None:
    idx = np.flatnonzero(trusted)
    if idx.size:
        ax.axvspan(t[0], t[idx[0]], color=UNTRUSTED_GREY, zorder=0, linewidth=0,
                   label="untrusted (estimator edges)" if label else None)
        ax.axvspan(t[idx[-1]], t[-1], color=UNTRUSTED_GREY, zorder=0, linewidth=0)


def _slip_line(ax, summary: dict, label: bool = True) -> None:
    t_slip = summary.get("t_slip")
    if t_slip is not None:
        ax.axvline(t_slip, color="k", linestyle=":", linewidth=0.9,
                   label=f"model slip onset, t = {t_slip:.4f} s" if label else None)


def _fmt(value) -> str:
    return "none" if value is None else format(value, ".4g")


def _curve_labels(summary: dict) -> dict[str, tuple[str, str, float, str]]:
    """Column -> (colour, line style, width, label naming the (mu, mu_d) the curve was drawn
    with)."""
    curves = (summary.get("model_fit") or {}).get("model_curves") or {}

    def label(key: str, what: str) -> str:
        c = curves.get(key)
        if not c:
            return f"model, {what}"
        if abs(c["mu"] - c["mu_d"]) <= 1e-12 * max(c["mu"], 1e-300):
            return f"model, {what}: mu = mu_d = {c['mu']:.4g}"
        ratio = f" ({c['mu_d'] / c['mu']:.2g} mu)" if key == "high" and c["mu"] > 0 else ""
        return f"model, {what}: mu = {c['mu']:.4g}, mu_d = {c['mu_d']:.3g}{ratio}"

    # the best fit first, broad and light: a bound's curve drawn on it stays visible
    return {"beta_model_rad": ("#7fb2e5", "-", 2.6, label("best", "best fit")),
            "beta_model_low_rad": ("C2", "--", 1.2, label("low", "lowest mu of the set")),
            "beta_model_high_rad": ("C3", "--", 1.2, label("high", "highest mu of the set"))}


def _beta_panel(ax, t, table, summary, sl: slice, labels: bool) -> None:
    """Measured beta and the model curves over ``sl``, y scaled to the measured samples."""
    beta = np.asarray(table["beta_clean_rad"], float)
    ax.plot(t[sl], beta[sl], ".", color="0.35", markersize=1.6, zorder=3,
            label="beta measured (lighting harmonics removed)" if labels else None)
    for key, (color, style, width, label) in _curve_labels(summary).items():
        y = np.asarray(table.get(key, []), float)
        if y.size and np.isfinite(y[sl]).any():
            ax.plot(t[sl], y[sl], color=color, linestyle=style, linewidth=width,
                    zorder=2 if key == "beta_model_rad" else 4,
                    label=label if labels else None)
    _slip_line(ax, summary, labels)
    ax.set_xlim(t[sl][0], t[sl][-1])
    lim = _limits(beta[sl], pad=0.12)
    if lim is not None:
        ax.set_ylim(*lim)
    ax.ticklabel_format(axis="y", useOffset=False)
    _style(ax, "beta [rad]")


def _fit_span(t: np.ndarray, table: dict) -> tuple[int, int] | None:
    fitted = np.flatnonzero(np.isfinite(np.asarray(table.get("beta_model_rad", []), float)))
    return (int(fitted[0]), int(fitted[-1])) if fitted.size > 1 else None


def plot_beta(table: dict, summary: dict, path: Path, figure_format: str = "png") -> Path:
    """The model fit of beta (report fig. 5.6): fit window, zoom on the slip, residual."""
    t = np.asarray(table["time_s"], float)
    span = _fit_span(t, table)
    t_slip = summary.get("t_slip")
    zoom = span is not None and t_slip is not None and t[span[0]] < t_slip < t[span[1]]
    rows = 3 if zoom else 2
    height = 2.3 * rows + 2.1
    fig = _figure(7.5, height, left_in=0.85, right_in=0.2, top_in=0.7, bottom_in=1.5,
                  hspace=0.42)
    axes = fig.subplots(rows, 1, height_ratios=[3, 2.2, 1.4][:rows] if zoom else [3, 1.4])
    i0, i1 = span if span is not None else (0, t.size - 1)
    _beta_panel(axes[0], t, table, summary, slice(i0, i1 + 1), labels=True)
    axes[0].set_title("(a) fit window", fontsize=FONT_PT, loc="left", y=1.0)
    if zoom:
        # the departure from sticking: 1.2x the fitted slip time before the onset, 0.4x after
        after = t[i1] - t_slip
        j0 = max(i0, int(np.searchsorted(t, t_slip - 1.2 * after)))
        j1 = min(i1, int(np.searchsorted(t, t_slip + 0.4 * after)))
        _beta_panel(axes[1], t, table, summary, slice(j0, max(j1, j0 + 2) + 1), labels=False)
        axes[1].set_title("(b) around the slip", fontsize=FONT_PT, loc="left", y=1.0)
    axr = axes[-1]
    res = np.asarray(table.get("beta_model_residual_rad", np.full(t.size, np.nan)), float)
    axr.plot(t[i0:i1 + 1], 1e3 * res[i0:i1 + 1], color="C0", linewidth=0.5)
    axr.axhline(0.0, color="k", linewidth=0.6)
    axr.set_xlim(t[i0], t[i1])
    lim = _limits(1e3 * res[i0:i1 + 1], pad=0.1)
    if lim is not None:
        m = max(abs(lim[0]), abs(lim[1]))
        axr.set_ylim(-m, m)
    _style(axr, "residual [mrad]")
    axr.set_title(f"({'c' if zoom else 'b'}) measured - best model", fontsize=FONT_PT,
                  loc="left", y=1.0)
    axr.set_xlabel("time [s]", fontsize=FONT_PT)
    conf = summary.get("confidence")
    title = "Ball model fit of beta"
    if conf is not None:
        title += (f": mu in [{_fmt(summary.get('mu_low'))}, {_fmt(summary.get('mu_high'))}] "
                  f"({100 * conf:g} % confidence, kinematic errors included)")
    fig.suptitle(title, fontsize=FONT_PT + 1, y=1.0 - 0.15 / height, va="top")
    fig.legend(loc="lower left", bbox_to_anchor=(0.85 / 7.5, 0.0), ncols=1, fontsize=LEGEND_PT,
               frameon=False)
    return save_figure(fig, path, figure_format)


def _bound_lines(ax, summary: dict) -> list[tuple[tuple, str]]:
    """Horizontal lines at both intervals' bounds (green low, red high; dashed: the model fit,
    dotted: the running max); one legend pair per interval."""
    rm = summary.get("running_max") or {}
    conf = summary.get("confidence")
    model = f"model fit, {100 * conf:g} %" if conf is not None else "model fit"
    pairs = []
    for src, style, who in ((summary, "--", model), (rm, ":", "running max")):
        lines = tuple(ax.axhline(src[key], color=color, linestyle=style, linewidth=1.0)
                      for key, color in (("mu_low", "C2"), ("mu_high", "C3"))
                      if src.get(key) is not None)
        if lines:
            pairs.append((lines, f"{who}: [{_fmt(src.get('mu_low'))}, "
                                 f"{_fmt(src.get('mu_high'))}]"))
    return pairs


def plot_kinematics(table: dict, summary: dict, path: Path, figure_format: str = "png") -> Path:
    """|omega|, |omega_dot| with its band, mu_req and the bounds (report figs. 5.7-5.9)."""
    t = np.asarray(table["time_s"], float)
    trusted = np.asarray(table["trusted"], dtype=bool)
    fig = _figure(8.0, 8.4, left_in=0.85, right_in=2.85, top_in=0.3, bottom_in=0.55,
                  hspace=0.28)
    a1, a2, a3 = fig.subplots(3, 1, sharex=True)
    omega = np.abs(np.asarray(table["omega_rad_s"], float))
    a1.plot(t, omega, color="C0", linewidth=1.0, label="|omega|")
    _style(a1, "|omega| [rad/s]")
    a1.set_ylim(*(_limits(omega[trusted]) or a1.get_ylim()))
    est = summary["estimator"]["name"]
    a1.set_title(f"(a) speed of the ABU ({est} estimator)", fontsize=FONT_PT, loc="left", y=1.0)

    k = summary["slip_detection"]["k_sigma"]
    a = np.abs(np.asarray(table["omega_dot_rad_s2"], float))
    s = np.asarray(table["sigma_omega_dot_rad_s2"], float)
    b = np.asarray(table.get("bias_omega_dot_rad_s2", np.zeros_like(s)), float)
    lo, hi = a - k * s - b, a + k * s + b
    a2.fill_between(t, lo, hi, color="C0", alpha=0.25, linewidth=0,
                    label=f"+-({k:g} sigma + truncation bound)")
    a2.plot(t, a, color="C0", linewidth=1.0, label="|omega_dot|")
    _style(a2, "|omega_dot| [rad/s^2]")
    a2.set_ylim(*(_limits(np.concatenate([lo[trusted], hi[trusted]]), floor=0.0)
                  or a2.get_ylim()))
    a2.set_title("(b) acceleration of the ABU, y axis scaled to the trusted samples",
                 fontsize=FONT_PT, loc="left", y=1.0)

    a3.fill_between(t, table["mu_req_lo"], table["mu_req_hi"], color="C0", alpha=0.25,
                    linewidth=0, label=f"mu_req +-{k:g} sigma")
    a3.plot(t, table["mu_req"], color="C0", linewidth=1.0, label="mu_req")
    running = (a3.plot(t, table["running_max_lo"], color="C2", linewidth=1.0)[0],
               a3.plot(t, table["running_max_hi"], color="C3", linewidth=1.0)[0])
    pairs = [(running, "running max of mu_req (low, high)")] + _bound_lines(a3, summary)
    top = np.asarray(table["mu_req_hi"], float)[trusted]
    bounds = [v for v in (summary.get("mu_high"), (summary.get("running_max") or {})
                          .get("mu_high")) if v is not None]
    if top.size and np.isfinite(top).any():
        a3.set_ylim(0.0, 1.1 * max([float(np.nanmax(top))] + bounds))
    _style(a3, "mu [-]")
    a3.set_title("(c) friction needed to stick, mu_req = (l - d/5)|omega_dot| / (l omega^2)",
                 fontsize=FONT_PT, loc="left", y=1.0)
    a3.set_xlabel("time [s]", fontsize=FONT_PT)
    for i, ax_ in enumerate((a1, a2, a3)):
        _shade_untrusted(ax_, t, trusted, label=i == 0)
        _slip_line(ax_, summary, label=i == 0)
        _legend_right(ax_, pairs if ax_ is a3 else ())
    a3.set_xlim(t[0], t[-1])
    return save_figure(fig, path, figure_format)


def plot_analysis(table: dict, summary: dict, out_dir: str | os.PathLike,
                  figure_format: str = "png") -> list[Path]:
    """Write ``beta`` and ``kinematics`` (``.png``, ``.pdf`` or ``.svg``) into ``out_dir``;
    returns their paths."""
    out = Path(out_dir)
    return [plot_beta(table, summary, out / "beta", figure_format),
            plot_kinematics(table, summary, out / "kinematics", figure_format)]
