"""What ``abu simulate`` writes: result.csv, summary.json (tagged with its kind and format
version), the plots, and the human-readable lines it prints (units in every line)."""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any

HZ = 2.0 * math.pi


def write_outputs(result, out: Path, figure_format: str = "png") -> list[Path]:
    """result.csv, summary.json and the figures (``figure_format`` png, pdf or svg) of an
    experiment into ``out``."""
    from abu_model.figure_files import check_figure_format
    from harness.experiments.plots import plot_experiment
    from harness.experiments.results_io import write_json, write_table_csv

    figure_format = check_figure_format(figure_format)
    out.mkdir(parents=True, exist_ok=True)
    written = [write_table_csv(out / "result.csv", result.table, result.units),
               write_json(out / "summary.json", tagged_summary(result.summary))]
    return written + plot_experiment(result.table, result.summary, out,
                                     figure_format=figure_format)


#: ``kind`` and ``format_version`` of an ``abu simulate`` summary.json (readers check them).
SIMULATE_KIND = "abu-simulate-summary"
SUMMARY_VERSION = 1


def tagged_summary(summary: dict[str, Any]) -> dict[str, Any]:
    """The summary with its ``kind`` and ``format_version`` first."""
    return {"kind": SIMULATE_KIND, "format_version": SUMMARY_VERSION, **summary}


def fmt_value(value: Any, unit: str = "", digits: int = 4) -> str:
    if value is None:
        return "none"
    return f"{value:.{digits}g}{(' ' + unit) if unit else ''}"


def describe(summary: dict[str, Any]) -> list[str]:
    """Human-readable lines (with units) of an experiment summary."""
    lines = [f"true mu = {fmt_value(summary['mu'])} [-]"]
    if "mu_low" in summary:
        lines.append(f"mu_low = {fmt_value(summary['mu_low'])} [-], "
                     f"mu_high = {fmt_value(summary['mu_high'])} [-]")
    if summary.get("mu_estimate") is not None:
        lines.append("mu estimate at the slip (eq. 4.1/4.2) = "
                     f"{fmt_value(summary['mu_estimate'], '', 7)} [-]")
    lines.append(f"first slip at t = {fmt_value(summary['t_slip'], 's', 9)}"
                 + (f", omega = {fmt_value(summary['omega_slip'], 'rad/s')}"
                    f" ({fmt_value(summary['omega_slip'] / HZ, 'Hz')}), "
                    f"omega_dot = {fmt_value(summary['alpha_slip'], 'rad/s^2')}"
                    if summary.get("t_slip") is not None else ""))
    if summary.get("t_restick") is not None:
        lines.append(f"sticks again at t = {fmt_value(summary['t_restick'], 's', 9)}")
    lines.append(f"switches: {len(summary['switches'])}; {summary.get('message', '')}")
    return lines
