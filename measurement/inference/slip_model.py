"""The ball's slip along the rim for candidate (mu, mu_d), driven by a measured ABU motion.

Two implementations of one model and discretisation: a compiled kernel (``_slipc.c``, built
by ``pip install -e .``), one candidate row at a time (~10x less CPU time in an analysis,
8.5-11x on seeds 1-3 of benchmarks/bench_slip_model.py), and the NumPy reference used where
the kernel is not built, vectorised over candidates and time (integrating factor + cumulative
sums; episodes of slip are looped, samples are not). They agree to rounding (the kernel
takes the integrating factor from each episode's onset, the reference from the call's first
column; <= 1e-13 of max |D|, tests/test_slip_kernel.py). Used by
:mod:`measurement.inference.infer_mu` (the model-based confidence set) and
:func:`measurement.inference.running_max.predicted_creep` (the report's creep lower bound).
"""
from __future__ import annotations

import sys

import numpy as np

try:  # the compiled kernel, built by `pip install -e .` where a C compiler is found
    from measurement.inference import _slipc
except ImportError:  # pragma: no cover - the NumPy reference gives the same results
    _slipc = None


def slip_direction(omega: np.ndarray, omega_dot: np.ndarray, trusted: np.ndarray) -> int:
    """Slip direction s of beta [-]: +1 while the ABU accelerates clockwise (omega_dot < 0),
    -1 the other way: the sign opposite to the median omega_dot [rad/s^2] over the trusted
    samples whose |mu_req| (omega_dot / omega^2, omega [rad/s]) is at least half its largest.
    (Not "the run-up only": the report's recommended drive sweeps mu_req by braking.)

    The ball slips where |mu_req| is large: those samples decide. The median over the whole
    record let a long one that ends with the drive settling at its last speed decide by the
    settling: on seed 20025 rendered with 12000 frames, 0.2 s of acceleration (mu_req up to
    0.02) against 2.4 s of a PI loop's slow overshoot and noise (mu_req < 0.003), s flipped and
    the analysis fitted the ball slipping the wrong way (no bound). On seeds 0-299 and
    2000-2299 of the family (3072 frames) both rules give the same s in every record."""
    od = np.asarray(omega_dot, float)
    trusted = np.asarray(trusted, bool)
    if not trusted.any():
        return 1
    q = np.abs(od) / np.maximum(np.asarray(omega, float) ** 2, 1e-12)
    top = trusted & (q >= 0.5 * float(np.max(q[trusted])))
    return -1 if float(np.median(od[top])) > 0 else 1


#: Least |omega| [share of the record's top speed so far] where the ball model holds.
SPINNING_SHARE = 0.2


def spinning_run(omega: np.ndarray, trusted: np.ndarray) -> np.ndarray:
    """``trusted`` [bool] ended where the ABU slows below :data:`SPINNING_SHARE` of its top
    speed so far (omega [rad/s]; a stop or a reversal of the rotation); the same array where
    nothing changes. The ball presses on
    its track with m omega^2 l: near omega = 0 mu_req (omega_dot / omega^2) grows without bound
    and the model says nothing (a run-up and run-down through 0 gave a "lower bound" of 705).
    The harsh family's drives never slow below 0.86 of their top speed (seeds 0-299 and
    2000-2299): there it changes nothing."""
    trusted = np.asarray(trusted, bool)
    idx = np.flatnonzero(trusted)
    if idx.size == 0:
        return trusted
    w = np.asarray(omega, float)[idx] * np.sign(np.asarray(omega, float)[idx[0]] or 1.0)
    slow = np.flatnonzero(w < SPINNING_SHARE * np.maximum.accumulate(np.abs(w)))
    if slow.size == 0:
        return trusted
    out = trusted.copy()
    out[idx[int(slow[0]):]] = False
    return out


def signed_mu_req(omega: np.ndarray, omega_dot: np.ndarray, l: float, d: float,
                  direction: int) -> np.ndarray:
    """q = (l - d/5) (-s omega_dot) / (l omega^2) [-]: mu_req, positive when it pushes along s."""
    w2 = np.maximum(np.asarray(omega, float) ** 2, 1e-12)
    return (l - d / 5.0) * (-float(direction) * np.asarray(omega_dot, float)) / (l * w2)


def slip_displacement(t: np.ndarray, q: np.ndarray, omega: np.ndarray, mu: np.ndarray,
                      mu_d: np.ndarray, direction: int, d_over_l: float, *,
                      max_episodes: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Displacement along the slip direction D [rad] for candidate pairs (mu, mu_d).

    Args:
        t: uniform times [s] (N,); the ball is stuck at t[0].
        q: signed mu_req (N,) [-], see :func:`signed_mu_req`.
        omega: ABU speed (N,) [rad/s].
        mu, mu_d: (M,) candidate static and sliding coefficients [-].
        direction: slip direction s (+1 / -1).
        d_over_l: ball diameter / path radius [-].
        max_episodes: slip episodes followed per candidate; None (default): every one to the
            end of the record. A cap freezes a candidate after its last followed re-stick, as
            if it stuck for good while q exceeds its mu again: a candidate with mu in q's noise
            (a few episodes on noise near q = 0) then escapes the record's real slip.

    Returns:
        (D, onset): (M, N) displacement [rad] (>= 0) and (M,) first onset time [s] (inf: none).
    """
    if _slipc is not None:
        # asarray first: ascontiguousarray would make a scalar mu 1-d, which the reference
        # refuses
        args = [np.asarray(a, dtype=float) for a in (t, q, omega, mu, mu_d)]
        t_, q_, w_, mu_, mud_ = args
        if (all(a.ndim == 1 for a in args) and t_.size >= 2 and q_.size == w_.size == t_.size
                and mud_.size == mu_.size):
            t_, q_, w_, mu_, mud_ = (np.ascontiguousarray(a) for a in args)
            disp, onset = np.empty((mu_.size, t_.size)), np.empty(mu_.size)
            # the reference follows none for a cap <= 0 and any int (the kernel: < 0 is all)
            cap = -1 if max_episodes is None else min(max(int(max_episodes), 0), sys.maxsize)
            try:
                _slipc.slip(t_, q_, w_, mu_, mud_, float(direction), float(d_over_l), cap,
                            disp, onset)
                return disp, onset
            except ValueError:  # NaN/inf or t[1] <= t[0]: refused before writing anything
                pass
    # no kernel, or inputs the kernel does not take: the reference (broadcasts, propagates
    # NaN or raises)
    return _slip_displacement_numpy(t, q, omega, mu, mu_d, direction, d_over_l,
                                    max_episodes=max_episodes)


def _slip_displacement_numpy(t: np.ndarray, q: np.ndarray, omega: np.ndarray, mu: np.ndarray,
                             mu_d: np.ndarray, direction: int, d_over_l: float, *,
                             max_episodes: int | None = None
                             ) -> tuple[np.ndarray, np.ndarray]:
    """The NumPy reference of :func:`slip_displacement` (same arguments; the same results to
    rounding)."""
    mu = np.asarray(mu, float)[:, None]
    mud = np.asarray(mu_d, float)[:, None]
    m_rows, n = mu.shape[0], t.size
    h = float(t[1] - t[0])
    w = np.asarray(omega, float)[None, :]
    qq = np.asarray(q, float)[None, :]
    # in place, the same operations in the same order as the plain expressions
    g = qq - mud
    g *= w * w
    g /= 1.4                                                 # (M, N) drive of u' [rad/s^2]
    c = mud * float(direction) * w
    c *= 2.0 - 0.2 * d_over_l
    c /= 1.4                                                 # u' = g - c u
    cumc = np.zeros((m_rows, n))
    np.cumsum(_trapezoids(c, h), axis=1, out=cumc[:, 1:])
    np.clip(cumc, -50.0, 50.0, out=cumc)
    e = np.exp(cumc, out=cumc)                               # integrating factor
    cs = np.zeros((m_rows, n))
    np.cumsum(_trapezoids(e * g, h), axis=1, out=cs[:, 1:])
    above = qq > mu                                          # (M, N) slip condition
    disp = np.zeros((m_rows, n))
    onset_first = np.full(m_rows, np.inf)
    rows = np.flatnonzero(above.any(axis=1))                 # rows with an onset ahead
    i_s = np.argmax(above[rows], axis=1)                     # ... and its sample
    start = np.zeros(rows.size, dtype=int)                   # where its search began
    episode = 0
    while max_episodes is None or episode < int(max_episodes):
        episode += 1
        # Only the rows with an onset still ahead are integrated, on the columns from just
        # before their earliest onset: the others add nothing, the leading columns are 0 and
        # sum exactly, so the numbers are those of the whole-array loop.
        if rows.size == 0:
            break
        sub = slice(None) if rows.size == m_rows else rows
        t_on, ep, c0, j = _episode(t, q, omega, mu[rows, 0], mud[rows, 0], g[rows, i_s],
                                   e[sub], cs[sub], i_s, start, h)
        onset_first[rows] = np.where(np.isinf(onset_first[rows]), t_on, onset_first[rows])
        disp[sub, c0:] = disp[sub, c0:] + ep
        # after the re-stick the next episode starts at j (a row that never re-sticks ends)
        keep = j < n
        rows, start = rows[keep], j[keep]
        cand = above[rows] & (np.arange(n)[None, :] >= start[:, None])
        has = cand.any(axis=1)
        rows, start, i_s = rows[has], start[has], np.argmax(cand[has], axis=1)
    return disp, onset_first


def _episode(t: np.ndarray, q: np.ndarray, omega: np.ndarray, mu: np.ndarray,
             mud: np.ndarray, g_is: np.ndarray, e: np.ndarray, cs: np.ndarray,
             i_s: np.ndarray, start: np.ndarray, h: float
             ) -> tuple[np.ndarray, np.ndarray, int, np.ndarray]:
    """One slip episode of the rows starting at sample ``i_s`` (q first above mu there; g_is
    the drive there): (onset time [s], displacement [rad] from column c0 on, c0, re-stick
    sample (n: none))."""
    n = t.size
    rows = np.arange(i_s.size)
    # sub-sample onset between i_s - 1 and i_s (q crosses mu there)
    prev = np.clip(i_s - 1, 0, n - 1)
    q0, q1 = q[prev], q[i_s]
    frac = np.where((i_s > start) & (q1 > q0), (mu - q0) / np.where(q1 > q0, q1 - q0, 1.0),
                    1.0)
    delta = (1.0 - np.clip(frac, 0.0, 1.0)) * h              # time from onset to t[i_s]
    t_on = t[i_s] - delta
    g_on = np.asarray(omega, float)[prev] ** 2 * (mu - mud) / 1.4
    u_is = 0.5 * (g_on + g_is) * delta                        # slip speed at t[i_s]
    d_is = 0.5 * u_is * delta
    c0 = int(prev.min())                                      # columns before c0 stay 0
    idx = np.arange(c0, n)[None, :]
    # u_n = [E_is u_is + CS_n - CS_is] / E_n for n >= i_s
    base = e[rows, i_s] * u_is - cs[rows, i_s]
    u = cs[:, c0:] + base[:, None]
    u /= e[:, c0:]
    live = idx >= i_s[:, None]
    stop = live & (u < 0.0)
    stop_any = stop.any(axis=1)
    j = np.where(stop_any, np.argmax(stop, axis=1) + c0, n)  # first re-stick sample
    u[~(live & (idx < j[:, None]))] = 0.0
    # displacement: trapezoid of u from t[i_s] on, plus the partial first interval
    ep = np.zeros(u.shape)
    np.cumsum(_trapezoids(u, h), axis=1, out=ep[:, 1:])
    ep -= ep[rows, i_s - c0][:, None]
    ep += d_is[:, None]
    ep[~live] = 0.0
    return t_on, ep, c0, j


def _trapezoids(a: np.ndarray, h: float) -> np.ndarray:
    """0.5 (a[:, k+1] + a[:, k]) h: the trapezoid areas between neighbouring columns."""
    out = a[:, 1:] + a[:, :-1]
    out *= 0.5
    out *= h
    return out
