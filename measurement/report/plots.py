"""Figures of one analysed record (PNG, Agg backend), two files so that plotting stays cheap
(matplotlib is imported only here, and only when plotting):

* ``beta.png`` -- the model fit (report fig. 5.6 made quantitative): measured beta with the
  lighting harmonics removed, the ball model's beta at the best (mu, mu_d) and at the two bounds
  of the confidence set, and the residual (measured - best model) in a second panel.
* ``kinematics.png`` -- |omega| (fig. 5.7), |omega_dot| with its noise + truncation band
  (fig. 5.8), and mu_req(t) with the running maxima of the report's interval, the model-based
  bounds and the running-max bounds (fig. 5.9). Untrusted edges are greyed.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
# The object-oriented API on the Agg canvas: no pyplot (its import and state machine cost
# ~0.3 s of the 2 s budget of `abu measure`).
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from abu_model.atomic_io import atomic_open

FIGURES = ("beta.png", "kinematics.png")


def _figure(rows: int, height: float, **kw):
    fig = Figure(figsize=(7, height))
    FigureCanvasAgg(fig)
    return fig, fig.subplots(rows, 1, sharex=True, **kw)


def _save(fig, path: Path) -> Path:
    with atomic_open(path, "wb") as handle:
        fig.savefig(handle, format="png", dpi=80)
    return path


def _shade_untrusted(ax, t: np.ndarray, trusted: np.ndarray) -> None:
    idx = np.flatnonzero(trusted)
    if idx.size:
        ax.axvspan(t[0], t[idx[0]], color="0.9", zorder=0)
        ax.axvspan(t[idx[-1]], t[-1], color="0.9", zorder=0)


def _slip_line(ax, summary: dict) -> None:
    if summary.get("t_slip") is not None:
        ax.axvline(summary["t_slip"], color="k", linestyle=":", linewidth=0.8,
                   label="model slip onset")


def plot_analysis(table: dict, summary: dict, out_dir: str | os.PathLike) -> list[Path]:
    """Write the figures into ``out_dir``; returns their paths."""
    out = Path(out_dir)
    t = np.asarray(table["time_s"])
    trusted = np.asarray(table["trusted"], dtype=bool)
    paths = []

    fig, (ax, axr) = _figure(2, 5.5, gridspec_kw={"height_ratios": [3, 1]})
    ax.plot(t, table["beta_clean_rad"], color="0.6", linewidth=0.6,
            label="beta measured, harmonics removed")
    fit = {"beta_model_rad": ("C0", "model, best (mu, mu_d)"),
           "beta_model_low_rad": ("C2", "model at mu_low"),
           "beta_model_high_rad": ("C3", "model at mu_high")}
    for key, (color, label) in fit.items():
        if key in table and np.isfinite(np.asarray(table[key], float)).any():
            ax.plot(t, table[key], color=color, linewidth=1.0, label=label)
    _slip_line(ax, summary)
    fitted = np.flatnonzero(np.isfinite(np.asarray(table.get("beta_model_rad", []), float)))
    if fitted.size > 1:
        # zoom on the fit window (stick + the first mrad of slip), where mu is decided
        i0, i1 = int(fitted[0]), int(fitted[-1])
        i2 = min(t.size - 1, i1 + (i1 - i0) // 4)
        seg = np.asarray(table["beta_clean_rad"], float)[i0: i2 + 1]
        pad = 0.1 * float(np.ptp(seg)) + 1e-9
        ax.set_xlim(t[i0], t[i2])
        ax.set_ylim(float(seg.min()) - pad, float(seg.max()) + pad)
    lo, hi = summary.get("mu_low"), summary.get("mu_high")
    conf = summary.get("confidence")
    title = "Ball model fit of beta"
    if conf is not None:
        title += (f": mu in [{'none' if lo is None else format(lo, '.4g')}, "
                  f"{'none' if hi is None else format(hi, '.4g')}] ({100 * conf:g} %)")
    ax.set_title(title, fontsize=9)
    ax.set_ylabel("beta [rad]")
    ax.legend(fontsize=7, loc="best")
    if "beta_model_residual_rad" in table:
        axr.plot(t, table["beta_model_residual_rad"], color="C0", linewidth=0.5)
    axr.axhline(0.0, color="k", linewidth=0.6)
    axr.set_ylabel("residual [rad]")
    axr.set_xlabel("time [s]")
    paths.append(_save(fig, out / "beta.png"))

    fig, (a1, a2, a3) = _figure(3, 8)
    a1.plot(t, np.abs(table["omega_rad_s"]), color="C0", linewidth=0.8)
    a1.set_ylabel("|omega| [rad/s]")
    a1.set_title(f"Kinematics ({summary['estimator']['name']}) and friction needed to stick",
                 fontsize=9)
    k = summary["slip_detection"]["k_sigma"]
    a = np.abs(table["omega_dot_rad_s2"])
    s = np.asarray(table["sigma_omega_dot_rad_s2"])
    b = np.asarray(table.get("bias_omega_dot_rad_s2", np.zeros_like(s)))
    a2.fill_between(t, a - k * s - b, a + k * s + b, color="C0", alpha=0.25,
                    label=f"+-({k:g} sigma + truncation bound)")
    a2.plot(t, a, color="C0", linewidth=0.8, label="|omega_dot|")
    a2.set_ylabel("|omega_dot| [rad/s^2]")
    a2.legend(fontsize=7, loc="best")
    a3.fill_between(t, table["mu_req_lo"], table["mu_req_hi"], color="C0", alpha=0.25,
                    label="mu_req band")
    a3.plot(t, table["mu_req"], color="C0", linewidth=0.8, label="mu_req")
    a3.plot(t, table["running_max_lo"], color="C2", linewidth=0.8, label="running max (low)")
    a3.plot(t, table["running_max_hi"], color="C3", linewidth=0.8, label="running max (high)")
    rm = summary.get("running_max") or {}
    for key, color, style, src in (("mu_low", "C2", "--", summary), ("mu_high", "C3", "--",
                                                                        summary),
                                   ("mu_low", "C2", ":", rm), ("mu_high", "C3", ":", rm)):
        if src.get(key) is not None:
            who = "model" if src is summary else "running max"
            a3.axhline(src[key], color=color, linestyle=style, linewidth=0.8,
                       label=f"{key} ({who}) = {src[key]:.4g}")
    finite = np.asarray(table["mu_req_hi"], float)[trusted]
    if finite.size and np.isfinite(finite).any():
        a3.set_ylim(0, 1.15 * np.nanmax(finite))
    a3.set_ylabel("mu [-]")
    a3.set_xlabel("time [s]")
    a3.legend(fontsize=6, loc="best")
    for ax_ in (a1, a2, a3):
        _shade_untrusted(ax_, t, trusted)
        _slip_line(ax_, summary)
    paths.append(_save(fig, out / "kinematics.png"))
    return paths
