"""PNG plots of a co-simulated experiment (report figs. 4.1-4.2, 4.4-4.7), without a display.

Each figure has time [s] on the x axis and SI units on the y axis (speeds also in Hz on a
secondary axis). Rows at a discontinuity (left then right limit at the same time) draw the
jump as a vertical segment. Files are written atomically.
"""
from __future__ import annotations

import io
import math
from pathlib import Path
from typing import Any, Mapping

import matplotlib

matplotlib.use("Agg")  # no display: tests and servers
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from abu_model.atomic_io import atomic_write_bytes  # noqa: E402

PLOTS = ("omega", "omega_dot", "beta", "beta_dot", "mu_req")


def save_png(fig, path: Path) -> Path:
    """Write ``fig`` as a PNG atomically and close it; returns the path."""
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=110, bbox_inches="tight")
    plt.close(fig)
    atomic_write_bytes(path, buffer.getvalue())
    return path


def _hz_axis(ax) -> None:
    ax.secondary_yaxis("right", functions=(lambda w: w / (2 * math.pi),
                                           lambda f: f * 2 * math.pi)).set_ylabel("[Hz]")


def _mark_slip(ax, summary: Mapping[str, Any]) -> None:
    if summary.get("t_slip") is not None:
        ax.axvline(summary["t_slip"], color="tab:red", lw=0.8, ls=":", label="first slip")


def plot_experiment(table: Mapping[str, np.ndarray], summary: Mapping[str, Any],
                    out_dir: str | Path, prefix: str = "") -> list[Path]:
    """Write omega, omega_dot, beta, beta_dot and mu_req plots into ``out_dir``.

    Returns the paths written (``<prefix>omega.png`` ...).
    """
    out = Path(out_dir)
    t = np.asarray(table["time"])
    title = summary.get("experiment", {}).get("motion", "")
    mode = summary.get("experiment", {}).get("theta_ref_mode")
    if mode:
        title = f"{title} ({mode})"
    written = []

    fig, ax = plt.subplots(figsize=(7, 3.6))
    if "omega_ref" in table:
        ax.plot(t, table["omega_ref"], color="0.6", lw=1, label="setpoint / prescribed")
    ax.plot(t, table["omega"], lw=1.3, label="omega")
    _mark_slip(ax, summary)
    ax.set(xlabel="time [s]", ylabel="omega [rad/s]", title=f"ABU speed {title}")
    _hz_axis(ax)
    ax.legend(loc="best", fontsize=8)
    written.append(save_png(fig, out / f"{prefix}omega.png"))

    fig, ax = plt.subplots(figsize=(7, 3.6))
    ax.plot(t, table["alpha"], lw=1.3)
    _mark_slip(ax, summary)
    ax.set(xlabel="time [s]", ylabel="omega_dot [rad/s^2]", title=f"ABU acceleration {title}")
    written.append(save_png(fig, out / f"{prefix}omega_dot.png"))

    fig, ax = plt.subplots(figsize=(7, 3.6))
    ax.plot(t, table["beta"], lw=1.3)
    _mark_slip(ax, summary)
    ax.set(xlabel="time [s]", ylabel="beta [rad]", title=f"Ball angle relative to the ABU {title}")
    written.append(save_png(fig, out / f"{prefix}beta.png"))

    fig, ax = plt.subplots(figsize=(7, 3.6))
    ax.plot(t, table["beta_dot"], lw=1.3)
    _mark_slip(ax, summary)
    ax.set(xlabel="time [s]", ylabel="beta_dot [rad/s]",
           title=f"Ball speed relative to the ABU {title}")
    written.append(save_png(fig, out / f"{prefix}beta_dot.png"))

    fig, ax = plt.subplots(figsize=(7, 3.6))
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
    ax.set(xlabel="time [s]", ylabel="mu_req = (l - d/5)|alpha| / (l omega^2) [-]",
           title=f"Friction needed to stick {title}")
    ax.legend(loc="best", fontsize=8)
    written.append(save_png(fig, out / f"{prefix}mu_req.png"))
    return written
