"""Figures of ``abu identify`` (fit and residuals) and ``abu design`` / ``abu next`` (bounds,
slip time): PNG, PDF or SVG (``figure_format``), legends outside the data."""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from harness.experiments.plots import legend_outside, new_figure, save_fig


def plot_identify(result, path: Path, figure_format: str = "png") -> Path:
    """Speed data, fitted speed and setpoint (top); residuals of the fitted quantity (bottom)."""
    fig, (ax, bx) = new_figure(2, 1, figsize=(8, 6), sharex=True,
                               gridspec_kw={"height_ratios": [2, 1]})
    t = result.omega_t
    ax.plot(t, result.omega_data / (2 * math.pi), ".", ms=2, color="0.5", label="record")
    ax.plot(t, result.omega_fit / (2 * math.pi), "-", color="tab:blue",
            label=f"fit ({result.drive.model})")
    grid = np.linspace(result.t[0], result.t[-1], 2000)
    ax.step(grid, result.setpoints.value(grid) / (2 * math.pi), where="post", color="tab:orange",
            lw=0.8, label="setpoint")
    ax.set_ylabel("omega [Hz]")
    legend_outside(ax)
    d = result.drive
    ax.set_title(f"Speed loop fit: zeta = {d.zeta:.4g}, omega_n = {d.omega_n:.4g} rad/s, "
                 f"tau_motor = {d.tau_motor:.3g} s", fontsize=9, loc="left")
    # the fitted quantity: the speed, or the angle of an optical sensor's pulses
    what = "speed residual [rad/s]" if result.kind == "omega" else "angle residual [rad]"
    bx.plot(result.t, result.residual, ".", ms=2, color="tab:red", label="record - fit")
    bx.axhline(0.0, color="k", lw=0.5)
    bx.set_ylabel(what)
    bx.set_xlabel("time [s]")
    bx.set_title(_wrap(f"residual check: {result.check['message']}", 90), fontsize=8, loc="left")
    legend_outside(bx)
    return save_fig(fig, path, figure_format)


def _wrap(text: str, width: int) -> str:
    import textwrap
    return "\n".join(textwrap.wrap(text, width)) or text


def plot_design(design, path: Path, check: Sequence[dict[str, Any]] | None = None,
                figure_format: str = "png") -> Path:
    """Predicted interval (top) and slip time (bottom) against mu; co-simulated checks as
    dots."""
    fig, (ax, bx) = new_figure(2, 1, figsize=(7.5, 6.5), sharex=True)
    mu = design.mu
    ax.fill_between(mu, design.mu_low, design.mu_high, color="tab:blue", alpha=0.3,
                    label="predicted interval")
    ax.plot(mu, mu, "k-", lw=0.8, label="true mu (a bound's target)")
    if check:
        for row in check:
            if row["mu_high"] is not None:
                ax.plot([row["mu"]] * 2, [row["mu_low"], row["mu_high"]], "r.-", ms=4)
        ax.plot([], [], "r.-", label="co-simulation bounds")
    # log axes for a prior range over a decade; a narrower one reads better on linear axes
    scale = "log" if float(np.max(mu)) > 10.0 * float(np.min(mu)) else "linear"
    ax.set_xscale(scale)
    ax.set_yscale(scale)
    ax.set_ylabel("bounds on mu [-]")
    legend_outside(ax)
    spec = design.spec
    bx.plot(mu, design.t_slip_s, "-", color="tab:blue", label="predicted slip")
    if check:
        bx.plot([r["mu"] for r in check if r["t_slip_s"] is not None],
                [r["t_slip_s"] for r in check if r["t_slip_s"] is not None], "r.",
                label="co-simulation")
    for k, y in enumerate((0.0, spec.record_s)):
        bx.axhline(y, color="k", lw=0.8, label="ends of the record" if k == 0 else None)
    for k, y in enumerate((spec.edge_s, spec.record_s - spec.edge_s)):
        bx.axhline(y, color="k", lw=0.5, ls=":",
                   label=f"{spec.edge_s:g} s from the ends" if k == 0 else None)
    bx.set_xscale(scale)
    bx.set_xlabel("mu [-]")
    bx.set_ylabel("slip time in the record [s]")
    legend_outside(bx)
    ax.set_title(f"Staircase: {design.omega0_hz:g} Hz -> {design.omega_end_hz:g} Hz, t0 = "
                 f"{design.t0_s:g} s, te = {design.te_s:.4g} s, step rounding "
                 f"'{design.rounding}'",
                 fontsize=9, loc="left")
    return save_fig(fig, path, figure_format)
