"""Figures of one analysed record, like the report's figures 5.6-5.9 (PNG, Agg backend).

* ``beta.png`` (fig. 5.6): measured beta, beta with the harmonic removed, the monotone fit, the
  stick level with the slip threshold, and t_slip_low / t_slip_high.
* ``omega.png`` (fig. 5.7): |omega| [rad/s].
* ``omega_dot.png`` (fig. 5.8): |omega_dot| [rad/s^2] with its k-sigma noise band; untrusted edges
  greyed.
* ``mu.png`` (fig. 5.9): mu_req(t), its error band, the running maxima and the bounds.
"""
from __future__ import annotations

import os
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from abu_model.atomic_io import atomic_open  # noqa: E402

FIGURES = ("beta.png", "omega.png", "omega_dot.png", "mu.png")


def _save(fig, path: Path) -> Path:
    with atomic_open(path, "wb") as handle:
        fig.savefig(handle, format="png", dpi=110)
    plt.close(fig)
    return path


def _mark_times(ax, summary: dict) -> None:
    for key, style, label in (("t_slip_low", ":", "t_slip_low (surely stuck)"),
                              ("t_slip_high", "--", "t_slip_high (surely slipping)")):
        if summary.get(key) is not None:
            ax.axvline(summary[key], color="k", linestyle=style, linewidth=1, label=label)


def _shade_untrusted(ax, t: np.ndarray, trusted: np.ndarray) -> None:
    idx = np.flatnonzero(trusted)
    if idx.size:
        ax.axvspan(t[0], t[idx[0]], color="0.9", zorder=0)
        ax.axvspan(t[idx[-1]], t[-1], color="0.9", zorder=0, label="untrusted edges")


def plot_analysis(table: dict, summary: dict, out_dir: str | os.PathLike) -> list[Path]:
    """Write the four figures into ``out_dir``; returns their paths."""
    out = Path(out_dir)
    t = np.asarray(table["time_s"])
    trusted = np.asarray(table["trusted"], dtype=bool)
    paths = []

    fig, ax = plt.subplots(figsize=(7, 4))
    ax.plot(t, table["beta_rad"], color="0.7", linewidth=0.6, label="beta measured")
    ax.plot(t, table["beta_clean_rad"], color="C0", linewidth=0.6, label="harmonic removed")
    ax.plot(t, table["beta_smooth_rad"], color="C3", linewidth=1.2, label="monotone fit")
    b0 = summary.get("beta_stick_rad")
    thr = summary["slip_detection"]["threshold_rad"]
    if b0 is not None:
        sign = summary.get("slip_direction", 1)
        ax.axhline(b0, color="k", linewidth=0.8)
        ax.axhline(b0 + sign * thr, color="k", linewidth=0.8, linestyle="-.",
                   label=f"slip threshold ({summary['slip_detection']['k_sigma']:g} sigma)")
    _mark_times(ax, summary)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("beta [rad]")
    ax.set_title("Relative angle of the ball (report fig. 5.6)")
    ax.legend(fontsize=7, loc="best")
    paths.append(_save(fig, out / "beta.png"))

    fig, ax = plt.subplots(figsize=(7, 4))
    ax.plot(t, np.abs(table["omega_rad_s"]), color="C0")
    _shade_untrusted(ax, t, trusted)
    _mark_times(ax, summary)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("|omega| [rad/s]")
    ax.set_title(f"ABU speed (report fig. 5.7), estimator {summary['estimator']['name']}")
    ax.legend(fontsize=7, loc="best")
    paths.append(_save(fig, out / "omega.png"))

    k = summary["slip_detection"]["k_sigma"]
    fig, ax = plt.subplots(figsize=(7, 4))
    a = np.abs(table["omega_dot_rad_s2"])
    s = np.asarray(table["sigma_omega_dot_rad_s2"])
    b = np.asarray(table.get("bias_omega_dot_rad_s2", np.zeros_like(s)))
    ax.fill_between(t, a - k * s - b, a + k * s + b, color="C0", alpha=0.25,
                    label=f"+-({k:g} sigma noise + estimator bias) band")
    ax.plot(t, a, color="C0", linewidth=0.8, label="|omega_dot|")
    _shade_untrusted(ax, t, trusted)
    _mark_times(ax, summary)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("|omega_dot| [rad/s^2]")
    ax.set_title("ABU acceleration (report fig. 5.8)")
    ax.legend(fontsize=7, loc="best")
    paths.append(_save(fig, out / "omega_dot.png"))

    fig, ax = plt.subplots(figsize=(7, 4))
    ax.fill_between(t, table["mu_req_lo"], table["mu_req_hi"], color="C0", alpha=0.25,
                    label="mu_req error band")
    ax.plot(t, table["mu_req"], color="C0", linewidth=0.8, label="mu_req")
    ax.plot(t, table["running_max_lo"], color="C2", linewidth=1, label="running max (low band)")
    ax.plot(t, table["running_max_hi"], color="C3", linewidth=1, label="running max (high band)")
    for key, color in (("mu_low", "C2"), ("mu_high", "C3")):
        if summary.get(key) is not None:
            ax.axhline(summary[key], color=color, linestyle="--", linewidth=0.8,
                       label=f"{key} = {summary[key]:.4g}")
    _shade_untrusted(ax, t, trusted)
    _mark_times(ax, summary)
    finite = np.asarray(table["mu_req_hi"])[trusted]
    if finite.size and np.isfinite(finite).any():
        ax.set_ylim(0, 1.15 * np.nanmax(finite))
    ax.set_xlabel("time [s]")
    ax.set_ylabel("mu [-]")
    ax.set_title("Friction needed to stick (report fig. 5.9)")
    ax.legend(fontsize=7, loc="best")
    paths.append(_save(fig, out / "mu.png"))
    return paths
