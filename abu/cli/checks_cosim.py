"""Checks of the co-simulation commands' options before anything expensive starts.

Each check names the option as typed, the value, the limit and why (issue 11). The limits come
from what a run implies: communication steps (about 0.4 ms each, benchmarks/bench_cosim.py),
setpoint steps, simulated time, and what the method can stand behind: the communication step
must resolve the closed loop (the controller's torque is held first-order between
communication points) and a ramp must not slip within its first communication steps.
"""
from __future__ import annotations

import argparse
import math
import re
import zipfile
from pathlib import Path
from typing import Iterable

from abu_model.errors import ParameterError
from abu_model.params import BallParams

from abu.cli.common import (MAX_COMM_STEPS, MAX_SETPOINT_STEPS, MAX_SIM_TIME_S, count_limit, finite,
                         in_range, positive)

HZ = 2.0 * math.pi
#: Fastest rotor speed accepted [Hz]: CD drives spin at most about 200 Hz (12,000 rpm).
MAX_SPEED_HZ = 1000.0
#: Largest omega * comm_step of the closed loop: the first-order hold of the controller torque
#: shifts the staircase bounds by about 1e-4 relative at 0.22 (report case, comm step 0.1 s),
#: 1.3 % at 0.66 (0.3 s), 3 % at 22 (10 s); at 0.1 the shift is below 2e-5.
MAX_LOOP_PHASE = 0.1
#: The ramp must run this many communication steps before the slip it measures.
MIN_STEPS_BEFORE_SLIP = 10
#: Earliest ramp slip [s] accepted with error-controlled steps: the eq. 4.1/4.2 estimate was exact
#: (1e-15 relative) down to a slip at 3.3e-9 s and 0 at 3.3e-10 s (jerk 1e11 rad/s^3).
MIN_T_SLIP_S = 1e-7
#: Pre-roll of a staircase run before t0 [s] (harness.experiments.staircase.PRE_ROLL).
PRE_ROLL_S = 0.05
#: Largest setpoint step [Hz] of table41 (the report's is 1 Hz).
MAX_STEP_HZ = 100.0
MIN_STEP_HZ = 1e-3
#: Accepted range of the coupling tolerance --tol [-] (harness.cosim.stepping; default 1e-9).
MIN_TOL, MAX_TOL = 1e-10, 1e-1
#: Largest closed-loop damping ratio / natural frequency [-, rad/s] the loop check may meet.
MAX_ZETA = 1000.0


def _speed(option: str, value_hz: float) -> float:
    finite(option, value_hz, "Hz")
    if abs(value_hz) > MAX_SPEED_HZ:
        raise ParameterError(option, value_hz, f"a speed of at most {MAX_SPEED_HZ:g} Hz in "
                             "magnitude (CD drives spin at most about 200 Hz)")
    return value_hz


def _comm_step(args: argparse.Namespace) -> float | None:
    """The fixed communication step, or None when the step is error-controlled (--tol)."""
    tol = getattr(args, "tol", None)
    if tol is not None:
        positive("--tol", tol, "")
        in_range("--tol", tol, MIN_TOL, MAX_TOL, "",
                 f"a coupling tolerance: below {MIN_TOL:g} the steps near switches reach the "
                 "resolution of the time axis (1e-11: 6 s, 1e-12: over 3 min, for bounds that "
                 f"no longer change); above {MAX_TOL:g} the "
                 "0.05 s step cap decides alone, the tolerance means nothing")
        return None
    value = getattr(args, "comm_step", None)
    if value is None:
        return None
    return positive("--comm-step", value, "s")


def _loop_rate(args: argparse.Namespace) -> float:
    """Fastest rate of the closed speed loop [rad/s]: max(omega_n, 2 zeta omega_n)."""
    zeta = positive("--zeta", args.zeta, "")
    in_range("--zeta", zeta, 0.0, MAX_ZETA, "", "a damping ratio")
    omega_n = positive("--omega-n", args.omega_n, "rad/s")
    return max(omega_n, 2.0 * zeta * omega_n)


def _check_loop_step(args: argparse.Namespace, h: float | None, span_s: float) -> None:
    rate = _loop_rate(args)
    h_max = MAX_LOOP_PHASE / rate
    if span_s / h_max > MAX_COMM_STEPS:
        bad = "--omega-n" if args.zeta <= 0.5 else "--zeta"
        raise ParameterError(bad, getattr(args, bad[2:].replace("-", "_")),
                             f"a closed loop slow enough to co-simulate: its rate "
                             f"{rate:.3g} rad/s needs communication steps <= {h_max:.3g} s, "
                             f"{span_s / h_max:.3g} of them for {span_s:.4g} s (at most "
                             f"{MAX_COMM_STEPS:.3g})")
    if h is not None and h > h_max:
        raise ParameterError("--comm-step", h,
                             f"a step <= {h_max:.3g} s = {MAX_LOOP_PHASE:g} / {rate:.3g} rad/s "
                             "(the closed loop's fastest rate: the torque held between "
                             "communication points must resolve it; coarser steps shift the "
                             "bounds silently, by 1.3 % at 0.3 s in the report's case)")


def check_plant(args: argparse.Namespace) -> None:
    """Finite plant options and a friction coefficient > 0."""
    for option in ("--mu", "--m", "--d", "--l", "--j-abu", "--tau-motor", "--beta0"):
        value = getattr(args, option[2:].replace("-", "_"))
        finite(option, value)
    if args.mu_d is not None:
        finite("--mu-d", args.mu_d)
    if args.mu <= 0:
        raise ParameterError("--mu", args.mu, "a friction coefficient > 0 (with mu = 0 the ball "
                             "slips at once: there is no stick period to measure)")
    in_range("--mu", args.mu, 0.0, 2.0, "", "dry friction coefficients are below about 1")
    in_range("--beta0", args.beta0, -1000.0, 1000.0, "rad", "an initial angle")
    if args.tau_motor > 1.0:
        raise ParameterError("--tau-motor", args.tau_motor, "a lag of at most 1 s (a CD drive's "
                             "motor answers in milliseconds)")


def check_staircase(args: argparse.Namespace) -> None:
    """Options of ``abu simulate --motion staircase`` (and the common ones)."""
    check_plant(args)
    w0 = _speed("--omega0-hz", args.omega0_hz)
    we = _speed("--omega-end-hz", args.omega_end_hz)
    step = positive("--step-hz", args.step_hz, "Hz")
    count_limit("--step-hz", step, abs(we - w0) / step, MAX_SETPOINT_STEPS, "setpoint steps",
                "each forces a communication point")
    t0 = finite("--t0", args.t0, "s")
    in_range("--t0", t0, -MAX_SIM_TIME_S, MAX_SIM_TIME_S, "s", "simulated time")
    te = positive("--te", args.te, "s")
    in_range("--te", te, 0.0, MAX_SIM_TIME_S, "s", "simulated time; the report's te is 1 s")
    t_end = t0 + te + 0.5 if args.t_end is None else finite("--t-end", args.t_end, "s")
    if t_end < t0 + te:
        raise ParameterError("--t-end", args.t_end,
                             f"a time >= t0 + te = {t0 + te:g} s (the end of the staircase; an "
                             "earlier end leaves setpoint steps unsimulated and reports bounds "
                             "of a shorter experiment)")
    span = t_end - min(0.0, t0 - PRE_ROLL_S)
    in_range("--t-end", t_end, -MAX_SIM_TIME_S, MAX_SIM_TIME_S, "s", "simulated time")
    h = _comm_step(args)
    if h is not None:
        count_limit("--comm-step", h, span / h, MAX_COMM_STEPS, "communication steps",
                    "about 0.4 ms of computing each")
    _check_loop_step(args, h, span)


def check_ramp(args: argparse.Namespace) -> None:
    """Options of ``abu simulate --motion ramp``."""
    check_plant(args)
    w0 = _speed("--omega0-hz", args.omega0_hz) * HZ
    if w0 == 0:
        raise ParameterError("--omega0-hz", args.omega0_hz, "a non-zero speed [Hz]")
    jerk = positive("--jerk", args.jerk, "rad/s^3")
    t_end = 1.0 if args.t_end is None else positive("--t-end", args.t_end, "s")
    in_range("--t-end", t_end, 0.0, MAX_SIM_TIME_S, "s", "simulated time")
    h = _comm_step(args)
    if h is not None:
        count_limit("--comm-step", h, t_end / h, MAX_COMM_STEPS, "communication steps",
                    "about 0.4 ms of computing each")
    b = BallParams(m=args.m, d=args.d, l=args.l, mu=args.mu, mu_d=args.mu_d)
    # Slip when (l - d/5) K t = mu l omega0^2 (omega changes little before it).
    t_slip = args.mu * b.l * w0 * w0 / ((b.l - b.d / 5.0) * jerk)
    if h is not None and t_slip < MIN_STEPS_BEFORE_SLIP * h:
        raise ParameterError("--jerk", jerk,
                             f"a ramp the co-simulation resolves: with it the ball slips at "
                             f"t = {t_slip:.3g} s, within {MIN_STEPS_BEFORE_SLIP} communication "
                             f"steps of {h:g} s (lower --jerk or --comm-step)")
    if t_slip < MIN_T_SLIP_S:
        raise ParameterError("--jerk", jerk,
                             f"a ramp the co-simulation resolves: with it the ball slips at "
                             f"t = {t_slip:.3g} s, below the {MIN_T_SLIP_S:g} s the master "
                             "resolves in time (the estimate was 0 at 3.3e-10 s)")


def check_table41(args: argparse.Namespace) -> None:
    """Options of ``abu table41``."""
    for mu in args.mu:
        finite("--mu", mu)
        if not 0 < mu <= 2.0:
            raise ParameterError("--mu", mu, "friction coefficients in (0, 2]")
    step = finite("--step-hz", args.step_hz, "Hz")
    if step <= 0:
        raise ParameterError("--step-hz", step, "a setpoint step > 0 Hz")
    in_range("--step-hz", step, MIN_STEP_HZ, MAX_STEP_HZ, "Hz", "the report's step is 1 Hz")
    t_step = finite("--t-step", args.t_step, "s")
    in_range("--t-step", t_step, -MAX_SIM_TIME_S, 100.0, "s",
             "the time of the step; the co-simulation check runs up to it")


def check_table41_speeds(rows: Iterable) -> None:
    """The |omega0| a table41 row found must be a speed an ABU reaches."""
    for row in rows:
        if row.omega0_hz > MAX_SPEED_HZ:
            raise ParameterError("--mu", row.mu, f"a friction coefficient whose threshold speed "
                                 f"is at most {MAX_SPEED_HZ:g} Hz (it needs {row.omega0_hz} Hz)")


#: Transports of a Dask scheduler address (distributed.comm).
SCHEDULER_SCHEMES = ("tcp", "tls", "ws", "wss", "ucx", "inproc")
_HOST = re.compile(r"(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9](?:[A-Za-z0-9.-]{0,252}[A-Za-z0-9])?)")


def check_scheduler_address(address: str | None) -> None:
    """``--scheduler`` is a Dask address ``[SCHEME://]HOST[:PORT]`` (syntax only: whether it
    answers is the sweep's to find out)."""
    if address is None:
        return
    expected = ("a Dask scheduler address [SCHEME://]HOST[:PORT], e.g. tcp://10.0.0.5:8786 "
                f"(SCHEME one of {', '.join(SCHEDULER_SCHEMES)}; PORT 1..65535)")
    rest = address.strip()
    if "://" in rest:
        scheme, rest = rest.split("://", 1)
        if scheme.lower() not in SCHEDULER_SCHEMES:
            raise ParameterError("--scheduler", address, expected)
        if scheme.lower() == "inproc":
            return
    host, port = rest, None
    if rest.startswith("["):
        end = rest.find("]")
        host, tail = rest[:end + 1], rest[end + 1:]
        if end < 0 or (tail and not tail.startswith(":")):
            raise ParameterError("--scheduler", address, expected)
        port = tail[1:] if tail else None
    elif ":" in rest:
        host, port = rest.rsplit(":", 1)
    if not _HOST.fullmatch(host or "") or (port is not None and not (
            port.isdigit() and 1 <= int(port) <= 65535)):
        raise ParameterError("--scheduler", address, expected)


def check_fmu_dir(option: str, fmu_dir: str | None, names: Iterable[str]) -> None:
    """``fmu_dir`` is a folder and each FMU in it is a zip archive with a modelDescription.xml
    (a missing one is built there); a folder of native FMUs holds all three and no other
    (:func:`harness.experiments.fmu_files.fmu_dir_kind`)."""
    if fmu_dir is None:
        return
    folder = Path(fmu_dir)
    if folder.exists() and not folder.is_dir():
        raise ParameterError(option, fmu_dir, "a folder (holding or receiving the FMUs)")
    for name in names:
        path = folder / f"{name}.fmu"
        if not path.exists():
            continue
        try:
            with zipfile.ZipFile(path) as archive:
                if "modelDescription.xml" not in archive.namelist():
                    raise zipfile.BadZipFile("no modelDescription.xml")
                bad = archive.testzip()
                if bad is not None:
                    raise zipfile.BadZipFile(f"member {bad} is damaged")
        except (zipfile.BadZipFile, OSError, EOFError, ValueError) as exc:
            raise ParameterError(option, fmu_dir, f"a folder of valid FMUs: '{path}' is not a "
                                 f"readable FMU ({exc}); delete it to have it rebuilt") from None
    from harness.experiments.fmu_files import fmu_dir_kind

    fmu_dir_kind(folder, option)  # one build, complete if native
