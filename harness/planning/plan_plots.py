"""PNG figures of ``abu identify`` (fit and residuals) and ``abu design`` (bounds, slip time)."""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Sequence

import matplotlib

matplotlib.use("Agg")  # no display: tests and servers
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from harness.experiments.plots import save_png  # noqa: E402


def plot_identify(result, path: Path) -> Path:
    """Speed data, fitted speed and setpoint (top); residuals of the fitted quantity (bottom)."""
    fig, (ax, bx) = plt.subplots(2, 1, figsize=(8, 6), sharex=True,
                                 gridspec_kw={"height_ratios": [2, 1]})
    t = result.omega_t
    ax.plot(t, result.omega_data / (2 * math.pi), ".", ms=2, color="0.5", label="record")
    ax.plot(t, result.omega_fit / (2 * math.pi), "-", color="tab:blue",
            label=f"fit ({result.drive.model})")
    grid = np.linspace(result.t[0], result.t[-1], 2000)
    ax.step(grid, result.setpoints.value(grid) / (2 * math.pi), where="post", color="tab:orange",
            lw=0.8, label="setpoint")
    ax.set_ylabel("omega [Hz]")
    ax.legend(loc="best", fontsize=8)
    d = result.drive
    ax.set_title(f"zeta = {d.zeta:.4g}, omega_n = {d.omega_n:.4g} rad/s, "
                 f"tau_motor = {d.tau_motor:.3g} s; {result.check['message'][:60]}", fontsize=8)
    unit = "rad/s" if result.kind == "omega" else "rad"
    bx.plot(result.t, result.residual, ".", ms=2, color="tab:red")
    bx.axhline(0.0, color="k", lw=0.5)
    bx.set_ylabel(f"residual [{unit}]")
    bx.set_xlabel("time [s]")
    return save_png(fig, path)


def plot_design(design, path: Path, check: Sequence[dict[str, Any]] | None = None) -> Path:
    """Predicted interval (left) and slip time (right) against mu; co-simulated checks as dots."""
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(10, 4))
    mu = design.mu
    ax.fill_between(mu, design.mu_low, design.mu_high, color="tab:blue", alpha=0.3,
                    label="predicted interval")
    ax.plot(mu, mu, "k-", lw=0.8, label="mu")
    if check:
        for row in check:
            if row["mu_high"] is not None:
                ax.plot([row["mu"]] * 2, [row["mu_low"], row["mu_high"]], "r.-", ms=4)
        ax.plot([], [], "r.-", label="co-simulation bounds")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("mu [-]")
    ax.set_ylabel("bounds [-]")
    ax.legend(fontsize=8)
    spec = design.spec
    bx.plot(mu, design.t_slip_s, "-", color="tab:blue", label="predicted slip")
    if check:
        bx.plot([r["mu"] for r in check if r["t_slip_s"] is not None],
                [r["t_slip_s"] for r in check if r["t_slip_s"] is not None], "r.",
                label="co-simulation")
    for y in (0.0, spec.record_s):
        bx.axhline(y, color="k", lw=0.8)
    for y in (spec.edge_s, spec.record_s - spec.edge_s):
        bx.axhline(y, color="k", lw=0.5, ls=":")
    bx.set_xscale("log")
    bx.set_xlabel("mu [-]")
    bx.set_ylabel("slip time in the record [s]")
    bx.legend(fontsize=8)
    fig.suptitle(f"{design.omega0_hz} Hz -> {design.omega_end_hz:g} Hz, t0 = {design.t0_s:g} s, "
                 f"te = {design.te_s:.4g} s, {design.rounding}", fontsize=9)
    return save_png(fig, path)
