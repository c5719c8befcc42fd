"""Combine the intervals [mu_low, mu_high] of several records (report sec. 5.3, fig. 5.11).

Given n intervals I_i = [L_i, R_i] (closed; a missing lower bound is 0, a missing upper bound +inf):

* **histogram** (report fig. 5.11): for a grid of mu, the number of intervals containing mu,
  c(mu) = #{i : L_i <= mu <= R_i}.
* **union hull**: [min L_i, max R_i], the range of mu contained in at least one interval (when the
  intervals overlap into one piece; the pieces of the union are listed too). The report's "total
  interval" [0.024, 0.035] over 12 runs reads best as this.
* **majority range**: the mu contained in more than half of the intervals (c(mu) > n/2), with its
  pieces; **common range**: the mu in all of them (the intersection, often empty: "the lower bound
  of one experiment exceeds the upper bound of another").
* **Turnbull NPMLE**: each record's mu is only known to lie in its interval (interval-censored
  data). The nonparametric maximum-likelihood estimate of the distribution of mu (Turnbull 1976,
  J. R. Stat. Soc. B 38, 290-295) puts all its mass on the *innermost intervals* (a left endpoint
  immediately followed by a right endpoint in the sorted list of endpoints) and is found by the
  self-consistency (EM) iteration p_j <- (1/n) sum_i a_ij p_j / sum_k a_ik p_k, a_ij = 1 if
  innermost interval j lies in I_i. Inside an innermost interval the mass is not located, so the
  median is an interval too.

All counts are computed exactly from the endpoints (the grid only draws the histogram).
"""
from __future__ import annotations

import csv
import math
import os
from pathlib import Path

import numpy as np

from abu_model import validate
from abu_model.errors import AbuError


#: Largest friction coefficient a bound may state (dry friction coefficients are below about 1).
MAX_MU = 100.0


class IntervalInputError(AbuError, ValueError):
    """A summary file or interval list cannot be read or holds an invalid interval."""


def _check_pair(where: str, lo, hi, *, text: bool = False) -> tuple[float, float]:
    """The interval [lo, hi] of a summary (JSON values: numbers or null) or of a CSV row
    (``text``: cells, empty for a missing bound). A JSON string or boolean is not a number."""
    def num(name, v, default):
        if v is None or (text and v.strip() == ""):
            return default
        place = f"{where}, {'column' if text else 'field'} '{name}'"
        expected = dict(lo=0.0, finite=False, error=IntervalInputError,
                        why="a friction coefficient; empty or null for no bound" if text
                        else "a friction coefficient; null for no bound")
        if text:
            if v.strip().lower() in ("inf", "+inf", "infinity") and name == "mu_high":
                return math.inf
            return validate.cell(v, place, lo=0.0, hi=MAX_MU, why=expected["why"],
                                 error=IntervalInputError)
        return validate.number(v, place, **{**expected, "finite": True, "hi": MAX_MU})
    lo_f = num("mu_low", lo, 0.0)
    hi_f = num("mu_high", hi, math.inf)
    if math.isinf(lo_f):
        raise IntervalInputError(f"{where}: mu_low = {lo!r}; expected a finite lower bound")
    if lo_f > hi_f:
        raise IntervalInputError(f"{where}: mu_low = {lo_f:g} exceeds mu_high = {hi_f:g}")
    if lo_f == 0.0 and math.isinf(hi_f):
        raise IntervalInputError(f"{where}: neither mu_low nor mu_high is given")
    return lo_f, hi_f


#: ``kind`` of the summary.json files of ``abu measure`` (see abu.cli.measure).
MEASURE_KIND = "abu-measure-summary"


def _check_kind(p: Path, data: object) -> None:
    """Refuse a JSON file that says it is something else (e.g. an ``abu simulate`` summary).

    A file without ``kind`` (hand-written intervals) is accepted unless it has the keys of a
    simulation summary (``experiment``, ``switches``).
    """
    if not isinstance(data, dict):
        raise IntervalInputError(f"{p}: expected a JSON object (an 'abu measure' summary), got "
                                 f"{type(data).__name__}")
    kind = data.get("kind")
    if kind is None and ("experiment" in data or "switches" in data):
        kind = "abu-simulate-summary"
    if kind is not None and kind != MEASURE_KIND:
        raise IntervalInputError(f"{p}: kind '{kind}' is not a measurement; expected the "
                                 f"summary.json of 'abu measure' (kind '{MEASURE_KIND}')")
    version = data.get("format_version", 1)
    if kind is not None and (not validate.is_number(version) or version != 1):
        raise IntervalInputError(f"{p}: format_version {version!r}; this version reads 1")


def read_intervals(paths: list[str | os.PathLike]) -> list[dict]:
    """Intervals from ``abu measure`` summary.json files and/or CSV files (mu_low,mu_high[,name]).

    Returns:
        list of {"name", "mu_low", "mu_high"} (0 / inf for a missing bound).
    """
    out: list[dict] = []
    for path in paths:
        p = Path(path)
        if not p.is_file():
            raise IntervalInputError(f"{p}: " + ("not a regular file" if p.exists()
                                                 else "file not found"))
        if p.suffix.lower() == ".csv":
            out.extend(_read_intervals_csv(p))
            continue
        try:
            text = p.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise IntervalInputError(f"{p}: not a readable JSON summary ({exc})") from None
        data = validate.json_object(text, str(p), "a JSON object (an 'abu measure' summary)",
                                    error=IntervalInputError)
        _check_kind(p, data)
        if not isinstance(data, dict) or "mu_low" not in data or "mu_high" not in data:
            raise IntervalInputError(f"{p}: expected an 'abu measure' summary with keys mu_low "
                                     "and mu_high")
        lo, hi = _check_pair(str(p), data["mu_low"], data["mu_high"])
        out.append({"name": str(p), "mu_low": lo, "mu_high": hi})
    if not out:
        raise IntervalInputError("no intervals given")
    return out


def _read_intervals_csv(p: Path) -> list[dict]:
    """Intervals of a CSV with columns mu_low,mu_high[,name] (one per data row)."""
    try:
        with open(p, newline="", encoding="utf-8") as handle:
            rows = [(n + 1, r) for n, r in enumerate(csv.reader(handle))
                    if r and any(c.strip() for c in r) and not r[0].lstrip().startswith("#")]
    except (UnicodeDecodeError, csv.Error) as exc:
        raise IntervalInputError(f"{p}: not a CSV text file ({exc})") from None
    head = [c.strip() for c in rows[0][1]] if rows else []
    if "mu_low" not in head or "mu_high" not in head:
        raise IntervalInputError(f"{p}: expected a header with columns mu_low,mu_high")
    validate.unique_names(head, f"{p}, header", error=IntervalInputError)
    if len(rows) < 2:
        raise IntervalInputError(f"{p}: a header and no data rows; expected one row "
                                 "mu_low,mu_high per record")
    il, ih = head.index("mu_low"), head.index("mu_high")
    iname = head.index("name") if "name" in head else None
    out = []
    for r_no, (line, row) in enumerate(rows[1:], start=1):
        where = f"{p}, data row {r_no} (line {line})"
        if len(row) != len(head):
            raise IntervalInputError(f"{where}: {len(row)} cells; expected {len(head)} as in "
                                     "the header")
        lo, hi = _check_pair(where, row[il], row[ih], text=True)
        name = row[iname].strip() if iname is not None else f"{p.name}:{r_no}"
        out.append({"name": name or f"{p.name}:{r_no}", "mu_low": lo, "mu_high": hi})
    return out


def coverage_count(intervals: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """c(mu): how many closed intervals (rows [L, R]) contain each mu."""
    iv = np.asarray(intervals, dtype=float)
    mu = np.asarray(mu, dtype=float)
    return ((iv[:, 0][None, :] <= mu[:, None]) & (mu[:, None] <= iv[:, 1][None, :])).sum(axis=1)


def level_set(intervals: np.ndarray, minimum: int) -> list[list[float]]:
    """Exact pieces [a, b] of {mu : c(mu) >= minimum}, from the endpoints."""
    iv = np.asarray(intervals, dtype=float)
    ends = np.unique(iv[np.isfinite(iv)])
    if ends.size == 0:
        return []
    # c is constant on the open gaps between endpoints: test each endpoint and each gap.
    points, kinds = [], []
    for k, e in enumerate(ends):
        points.append(e); kinds.append(("point", e, e))
        if k + 1 < ends.size:
            points.append(0.5 * (e + ends[k + 1])); kinds.append(("gap", e, ends[k + 1]))
    if np.isinf(iv[:, 1]).any():
        points.append(ends[-1] + 1.0); kinds.append(("gap", ends[-1], math.inf))
    counts = coverage_count(iv, np.array(points))
    pieces: list[list[float]] = []
    for (kind, a, b), c in zip(kinds, counts):
        if c < minimum:
            continue
        if pieces and pieces[-1][1] == a:
            pieces[-1][1] = b
        else:
            pieces.append([a, b])
    return pieces


def innermost_intervals(intervals: np.ndarray) -> np.ndarray:
    """Turnbull's innermost intervals [q, p] (rows) of closed intervals [L, R]."""
    iv = np.asarray(intervals, dtype=float)
    # Left endpoints sort before right endpoints at the same value (closed intervals).
    events = sorted([(lo, 0) for lo in iv[:, 0]] + [(hi, 1) for hi in iv[:, 1]])
    out = []
    for (v1, k1), (v2, k2) in zip(events, events[1:]):
        if k1 == 0 and k2 == 1:
            out.append((v1, v2))
    return np.array(sorted(set(out)), dtype=float).reshape(-1, 2)


def turnbull(intervals: np.ndarray, *, tol: float = 1e-10, max_iter: int = 100000) -> dict:
    """Turnbull's NPMLE of the distribution of mu from interval-censored observations.

    Returns:
        dict with ``innermost`` (list of [q, p]), ``mass`` (probabilities), ``support`` (the
        innermost intervals with mass > 1e-6, with their mass), ``median`` ([a, b], the range
        in which the NPMLE's median lies), ``loglik`` and ``iterations``.
    """
    iv = np.asarray(intervals, dtype=float)
    n = iv.shape[0]
    inner = innermost_intervals(iv)
    a = ((iv[:, 0][:, None] <= inner[None, :, 0]) & (inner[None, :, 1] <= iv[:, 1][:, None]))
    a = a.astype(float)
    p = np.full(inner.shape[0], 1.0 / inner.shape[0])
    it = 0
    for it in range(1, max_iter + 1):
        denom = a @ p
        new = p * (a / denom[:, None]).sum(axis=0) / n
        if np.max(np.abs(new - p)) < tol:
            p = new
            break
        p = new
    p = p / p.sum()
    cdf = np.cumsum(p)
    j = int(np.searchsorted(cdf, 0.5 - 1e-9))
    if abs(cdf[j] - 0.5) < 1e-9 and j + 1 < inner.shape[0]:
        # The CDF sits at exactly 1/2 between two innermost intervals: the median is the gap.
        median = [float(inner[j, 1]), float(inner[j + 1, 0])]
    else:
        median = [float(inner[j, 0]), float(inner[j, 1])]
    keep = p > 1e-6
    return {
        "innermost": inner.tolist(), "mass": p.tolist(),
        "support": [{"interval": inner[k].tolist(), "mass": float(p[k])}
                    for k in np.flatnonzero(keep)],
        "median": median, "loglik": float(np.sum(np.log(a @ p))), "iterations": it,
    }


def combine_summaries(intervals: list[dict], *, bins: int = 100) -> dict:
    """The combined result (JSON-ready): histogram, ranges and the Turnbull estimate."""
    if bins < 2:
        raise IntervalInputError(f"--bins = {bins}: expected at least 2 grid points")
    iv = np.array([[r["mu_low"], r["mu_high"]] for r in intervals], dtype=float)
    n = iv.shape[0]
    finite = iv[np.isfinite(iv)]
    span_lo, span_hi = float(finite.min()), float(finite.max())
    pad = 0.05 * (span_hi - span_lo) if span_hi > span_lo else 0.05 * span_hi
    grid = np.linspace(max(0.0, span_lo - pad), span_hi + pad, bins)
    counts = coverage_count(iv, grid)
    union = level_set(iv, 1)
    majority = level_set(iv, n // 2 + 1)
    common = level_set(iv, n)
    top = int(coverage_count(iv, np.unique(finite)).max())
    return {
        "n_records": n,
        "n_complete": int(np.sum((iv[:, 0] > 0) & np.isfinite(iv[:, 1]))),
        "intervals": [{"name": r["name"], "mu_low": r["mu_low"],
                       "mu_high": None if math.isinf(r["mu_high"]) else r["mu_high"]}
                      for r in intervals],
        "histogram": {"mu": grid.tolist(), "count": counts.astype(int).tolist()},
        "union_hull": [union[0][0], union[-1][1]] if union else [None, None],
        "union_pieces": union,
        "majority_range": [majority[0][0], majority[-1][1]] if majority else None,
        "majority_pieces": majority,
        "common_range": common[0] if common else None,
        "max_count": top,
        "max_count_pieces": level_set(iv, top),
        "turnbull": turnbull(iv),
        "units": {"mu*": "1", "count": "number of intervals"},
    }


def plot_histogram(result: dict, path: str | os.PathLike, figure_format: str = "png") -> Path:
    """Draw the histogram of fig. 5.11 (the exact step function of the records' intervals, not
    the grid's), the ranges and the Turnbull median interval; PNG, PDF or SVG (the suffix of
    ``path`` is replaced by ``figure_format``'s). Returns the path written."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.ticker import MaxNLocator

    from abu_model.figure_files import save_figure

    n = int(result["n_records"])
    grid = np.asarray(result["histogram"]["mu"], float)
    iv = np.array([[r["mu_low"], math.inf if r["mu_high"] is None else r["mu_high"]]
                   for r in result["intervals"]], dtype=float)
    ends = iv[np.isfinite(iv)]
    edges = np.unique(np.concatenate([grid[[0, -1]], ends[(ends > grid[0]) & (ends < grid[-1])]]))
    counts = coverage_count(iv, 0.5 * (edges[:-1] + edges[1:]))
    width, height = 8.0, 4.2
    fig = Figure(figsize=(width, height))
    FigureCanvasAgg(fig)
    fig.subplots_adjust(left=0.7 / width, right=1 - 2.75 / width, top=1 - 0.45 / height,
                        bottom=0.6 / height)
    ax = fig.subplots()
    ax.stairs(counts, edges, fill=True, color="C0", alpha=0.35, linewidth=0)
    ax.stairs(counts, edges, color="C0", linewidth=1.4, label="records whose interval holds mu")
    u = result["union_hull"]
    if u[0] is not None:
        ax.axvspan(u[0], u[1] if u[1] is not None and math.isfinite(u[1]) else grid[-1],
                   color="0.9", zorder=0, linewidth=0, label="in at least one (union hull)")
    for k, (a, b) in enumerate(result["majority_pieces"]):
        ax.axvspan(a, b, color="C1", alpha=0.22, zorder=0, linewidth=0,
                   label="in more than half (majority range)" if k == 0 else None)
    med = result["turnbull"]["median"]
    if med[1] > med[0]:
        ax.axvspan(med[0], med[1], ymin=0, ymax=1, facecolor="none", edgecolor="C3",
                   hatch="///", linewidth=1.2, zorder=3,
                   label=f"Turnbull median in [{med[0]:.4g}, {med[1]:.4g}]")
    else:
        ax.axvline(med[0], color="C3", linewidth=1.2, label=f"Turnbull median = {med[0]:.4g}")
    ax.axhline(n / 2, color="k", linewidth=0.7, linestyle=":", label=f"half of the {n} records")
    ax.set_xlim(grid[0], grid[-1])
    ax.set_ylim(0, n + 0.5)
    ax.yaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlabel("mu [-]", fontsize=9)
    ax.set_ylabel("number of intervals holding mu", fontsize=9)
    ax.tick_params(labelsize=8.5)
    ax.set_title(f"Intervals on mu of {n} records (report fig. 5.11)", fontsize=10, loc="left",
                 y=1.0)
    ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8, frameon=False,
              borderaxespad=0.0)
    return save_figure(fig, path, figure_format)
