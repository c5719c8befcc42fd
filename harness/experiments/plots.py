"""Figures of a co-simulated experiment (report figs. 4.1-4.2, 4.4-4.7), without a display:
PNG at :data:`abu_model.figure_files.PNG_DPI` dpi, or PDF / SVG (``figure_format``).

Each figure has time [s] on the x axis and SI units on the y axis (speeds also in Hz on a
secondary axis); legends sit right of the data, the layout is constrained (no clipped label).
Rows at a discontinuity (left then right limit at the same time) draw the jump as a vertical
segment. Files are written atomically.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Mapping

import matplotlib

matplotlib.use("Agg")  # no display: tests and servers
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from abu_model.figure_files import save_figure  # noqa: E402

PLOTS = ("omega", "omega_dot", "beta", "beta_dot", "mu_req")


#: Size of one time-series figure [in] and its fonts [pt].
FIGSIZE = (7.5, 3.6)
LEGEND_PT = 8


def new_figure(nrows: int = 1, ncols: int = 1, figsize=FIGSIZE, **kw):
    """(figure, axes) with a constrained layout (room for outside legends and every label)."""
    return plt.subplots(nrows, ncols, figsize=figsize, layout="constrained", **kw)


def legend_outside(ax) -> None:
    """The legend right of the axes (and of a secondary axis), outside the data."""
    fig = ax.figure
    if len(fig.axes) == 1:   # the layout engine places a figure legend beside everything
        handles, labels = ax.get_legend_handles_labels()
        fig.legend(handles, labels, loc="outside right upper", fontsize=LEGEND_PT,
                   frameon=False)
        return
    ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=LEGEND_PT, frameon=False,
              borderaxespad=0.0)


def save_fig(fig, path: Path, figure_format: str = "png") -> Path:
    """Write ``fig`` (suffix of ``path`` replaced by ``figure_format``'s) atomically and close
    it; returns the path written."""
    try:
        return save_figure(fig, path, figure_format)
    finally:
        plt.close(fig)


def _hz_axis(ax) -> None:
    ax.secondary_yaxis("right", functions=(lambda w: w / (2 * math.pi),
                                           lambda f: f * 2 * math.pi)).set_ylabel("omega [Hz]")


def _mark_slip(ax, summary: Mapping[str, Any]) -> None:
    if summary.get("t_slip") is not None:
        ax.axvline(summary["t_slip"], color="tab:red", lw=0.8, ls=":", label="first slip")


def plot_experiment(table: Mapping[str, np.ndarray], summary: Mapping[str, Any],
                    out_dir: str | Path, prefix: str = "",
                    figure_format: str = "png") -> list[Path]:
    """Write omega, omega_dot, beta, beta_dot and mu_req figures into ``out_dir``.

    Returns the paths written (``<prefix>omega.png`` ..., or ``.pdf`` / ``.svg``).
    """
    out = Path(out_dir)
    t = np.asarray(table["time"])
    title = summary.get("experiment", {}).get("motion", "")
    mode = summary.get("experiment", {}).get("theta_ref_mode")
    if mode:
        title = f"{title} ({mode})"
    title = f", {title}" if title else ""
    written = []

    fig, ax = new_figure()
    if "omega_ref" in table:
        ax.plot(t, table["omega_ref"], color="0.6", lw=1, label="setpoint / prescribed")
    ax.plot(t, table["omega"], lw=1.3, label="omega")
    _mark_slip(ax, summary)
    ax.set(xlabel="time [s]", ylabel="omega [rad/s]", title=f"ABU speed{title}")
    _hz_axis(ax)
    legend_outside(ax)
    written.append(save_fig(fig, out / f"{prefix}omega", figure_format))

    # the plain time series: column, its label, the y-axis label, the title, the file stem
    for column, label, ylabel, heading, stem in (
            ("alpha", "omega_dot", "omega_dot [rad/s^2]", "ABU acceleration", "omega_dot"),
            ("beta", "beta", "beta [rad]", "Ball angle relative to the ABU", "beta"),
            ("beta_dot", "beta_dot", "beta_dot [rad/s]", "Ball speed relative to the ABU",
             "beta_dot")):
        fig, ax = new_figure()
        ax.plot(t, table[column], lw=1.3, label=label)
        _mark_slip(ax, summary)
        ax.set(xlabel="time [s]", ylabel=ylabel, title=f"{heading}{title}")
        legend_outside(ax)
        written.append(save_fig(fig, out / f"{prefix}{stem}", figure_format))

    fig, ax = new_figure()
    stuck = np.asarray(table["mode"]) == 0
    mu_req = np.where(stuck, table["mu_req"], np.nan)
    ax.plot(t, mu_req, lw=1.3, label="mu_req while stuck")
    for key, color, label in (("mu_low", "tab:green", "mu_low"), ("mu_high", "tab:red", "mu_high"),
                              ("mu", "k", "true mu"), ("mu_estimate", "tab:purple", "mu estimate")):
        value = summary.get(key)
        if value is not None and math.isfinite(value):
            ax.axhline(value, color=color, lw=0.9, ls="--" if key != "mu" else "-",
                       label=f"{label} = {value:.4g}")
    _mark_slip(ax, summary)
    ax.set(xlabel="time [s]", ylabel="mu_req [-]",
           title=f"Friction needed to stick{title}\nmu_req = (l - d/5)|omega_dot| / (l omega^2)")
    legend_outside(ax)
    written.append(save_fig(fig, out / f"{prefix}mu_req", figure_format))
    return written
