"""Speed and accuracy of the staircase co-simulation against the monolithic SciPy reference.

    python benchmarks/bench_cosim.py [--pairs N] [--tol TOL] [--theta-ref MODE]

Runs the report's staircase experiment (mu = 2.75e-3, -17 Hz -> -22 Hz in 1 s) as
co-simulation (the toolkit's master at the default tolerance and the staircase's default
Taylor hold of the torque, FMUs reused between runs) and
as one SciPy ODE (abu_model.reference), alternating the two in the same process for N pairs
(default 12), and prints the median of the pair ratios, the communication steps, rollbacks
and FMI calls, and the differences of the bounds and of every switch time from the
reference. Then a plain fixed-step fmpy master (get outputs and set inputs in connection
order, fmi2DoStep all; no event landing, no rollback) at 1 ms and 0.1 ms, with its time and
its slip-time and bound errors beside ours. FMUs are built and loaded before timing.
"""
from __future__ import annotations

import argparse
import math
import statistics
import sys
import tempfile
import time

from bench_args import positive_int  # the scripts' folder is on sys.path

from fmpy.fmi2 import FMU2Slave
from fmpy import read_model_description

from abu_model.params import PlantParams
from abu_model.reference import simulate_staircase_reference
from fmus.build import build_fmus
from harness.experiments.staircase import StaircaseExperiment, run_staircase
from harness.cosim.fmi import extracted
from harness.cosim.stepping import DEFAULT_TOL

HZ = 2.0 * math.pi


def _reference(exp: StaircaseExperiment):
    return simulate_staircase_reference(exp.plant, exp.controller, exp.staircase, exp.t_end,
                                        t_start=exp.t_start)


def plain_master(exp: StaircaseExperiment, fmus: dict, h: float) -> dict:
    """A plain fixed-step master on fmpy: at every point get each connection's output and
    set its input (in the system's connection order), then fmi2DoStep every FMU by h [s].

    Returns the wall time [s] and the bounds read the plain way: mu_low = largest mu_req
    while stuck before the first slip, mu_high = mu_req at the first point in slip, t_slip =
    the plant's t_last_switch.
    """
    system = exp.system(fmus)
    slaves, variables = {}, {}
    for comp in system.components:
        md = read_model_description(str(comp.fmu), validate=False)
        slave = FMU2Slave(guid=md.guid, unzipDirectory=str(extracted(comp.fmu.resolve())),
                          modelIdentifier=md.coSimulation.modelIdentifier,
                          instanceName=comp.name)
        slave.instantiate()
        variables[comp.name] = {v.name: v for v in md.modelVariables}
        slaves[comp.name] = slave
    start = time.perf_counter()
    for comp in system.components:
        slave, var = slaves[comp.name], variables[comp.name]
        slave.setupExperiment(startTime=exp.t_start, stopTime=exp.t_end)
        for name, value in comp.parameters.items():
            v = var[name]
            if v.type == "Real":
                slave.setReal([v.valueReference], [float(value)])
            elif v.type == "Integer":
                slave.setInteger([v.valueReference], [int(value)])
            else:
                slave.setBoolean([v.valueReference], [bool(value)])
        slave.enterInitializationMode()
    for slave in slaves.values():
        slave.exitInitializationMode()
    links = []
    for conn in system.connections:
        (sc, sn), (dc, dn) = conn.src.split(".", 1), conn.dst.split(".", 1)
        links.append((slaves[sc], variables[sc][sn].valueReference,
                      slaves[dc], variables[dc][dn].valueReference))
    plant, pv = slaves["plant"], variables["plant"]
    probe = [pv[n].valueReference for n in ("mu_req", "t_last_switch")]
    mode_vr = [pv["mode"].valueReference]
    n = round((exp.t_end - exp.t_start) / h)
    mu_low, mu_high, t_slip = 0.0, None, None
    for k in range(n + 1):
        t = exp.t_start + k * h
        for src, svr, dst, dvr in links:
            dst.setReal([dvr], src.getReal([svr]))
        mu_req, t_last = plant.getReal(probe)
        mode = plant.getInteger(mode_vr)[0]
        if mode == 0 and mu_high is None:
            mu_low = max(mu_low, mu_req)
        elif mode != 0 and mu_high is None:
            mu_high, t_slip = mu_req, t_last
        if k < n:
            for slave in slaves.values():
                slave.doStep(t, h)
    elapsed = time.perf_counter() - start
    for slave in slaves.values():
        slave.terminate()
        slave.fmi2FreeInstance(slave.component)  # no dlclose (see harness/cosim/master.py)
    return {"time": elapsed, "mu_low": mu_low, "mu_high": mu_high, "t_slip": t_slip,
            "steps": n}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pairs", type=positive_int, default=12, help="alternating pairs (default 12)")
    parser.add_argument("--tol", type=float, default=None,
                        help=f"coupling tolerance (default the master's, {DEFAULT_TOL:g})")
    parser.add_argument("--theta-ref", choices=["integral", "thesis"], default="integral")
    args = parser.parse_args(argv)

    exp = StaircaseExperiment(PlantParams(), -17 * HZ, -22 * HZ, theta_ref_mode=args.theta_ref,
                              tol=args.tol)
    with tempfile.TemporaryDirectory() as tmp:
        fmus = build_fmus(tmp)
        order = len(exp.system(fmus).holds[0].derivatives)
        run_staircase(exp, fmus)  # warm-up: extraction, imports, instances loaded for reuse
        _reference(exp)
        ratios, t_co, t_ref = [], [], []
        for _ in range(args.pairs):
            start = time.perf_counter()
            cosim = run_staircase(exp, fmus)
            t_co.append(time.perf_counter() - start)
            start = time.perf_counter()
            ref = _reference(exp)
            t_ref.append(time.perf_counter() - start)
            ratios.append(t_co[-1] / t_ref[-1])
        plain = {h: plain_master(exp, fmus, h) for h in (1e-3, 1e-4)}
    s, c = cosim.summary, cosim.summary["cosim"]
    print(f"staircase experiment, {args.theta_ref} PI, {exp.t_end - exp.t_start:g} s simulated; "
          f"tolerance {s['experiment']['tol']:g}, Taylor hold of order {order}; "
          f"{args.pairs} alternating pairs")
    print(f"co-simulation: median {statistics.median(t_co) * 1e3:.1f} ms ({c['steps']} steps, "
          f"{c['rollbacks']} rollbacks of which {c['rejected']} rejected steps, "
          f"{c['do_steps']} rounds of fmi2DoStep, {c['fmi_calls']} FMI calls = "
          f"{c['fmi_calls'] / c['steps']:.1f} per step, "
          f"{1e6 * statistics.median(t_co) / c['steps']:.0f} us per step)")
    print(f"monolithic reference: median {statistics.median(t_ref) * 1e3:.1f} ms")
    print(f"ratio co-simulation / reference: median of pairs {statistics.median(ratios):.2f} "
          f"(min {min(ratios):.2f}, max {max(ratios):.2f}; target <= 2)")
    d_low, d_high = s["mu_low"] / ref.mu_low - 1, s["mu_high"] / ref.mu_high - 1
    print(f"bounds vs reference: mu_low {s['mu_low']:.8e} ({d_low:+.1e} rel.), mu_high "
          f"{s['mu_high']:.8e} ({d_high:+.1e} rel.); target within 1e-6")
    for ours, theirs in zip(s["switches"], ref.switches):
        print(f"switch {theirs.from_mode:+d} -> {theirs.to_mode:+d} at {theirs.time:.9f} s: "
              f"difference {ours['time_s'] - theirs.time:+.1e} s")
    for h, p in plain.items():
        print(f"plain fixed-step fmpy master, h = {h:g} s: {p['time'] * 1e3:.0f} ms "
              f"({p['time'] / statistics.median(t_ref):.1f} x reference, {p['steps']} steps); "
              f"t_slip {p['t_slip']:.9f} s ({p['t_slip'] - ref.t_slip:+.1e} s), mu_low "
              f"{p['mu_low'] / ref.mu_low - 1:+.1e} rel., mu_high "
              f"{p['mu_high'] / ref.mu_high - 1:+.1e} rel.")
    print(f"ours (default tolerance): t_slip {s['t_slip'] - ref.t_slip:+.1e} s, mu_low "
          f"{d_low:+.1e} rel., mu_high {d_high:+.1e} rel.")
    return 0


if __name__ == "__main__":
    sys.exit(main())
