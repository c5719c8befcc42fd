"""The generic co-simulation master on three tiny pythonfmu slaves built here.

The slaves mirror the ABU system's structure (a plant with a state output and a
feedthrough output, a controller whose outputs depend on its inputs, a step reference):

* ``HtIntegrator``: x' = u with u first-order held (inputs u, u_rate); outputs x (no
  feedthrough), y = u (feedthrough), and a "switch" each time x crosses a multiple of
  ``level`` upwards, located exactly inside the step (switch_count, t_last_switch, mode).
* ``HtGain``: u = k (r - x_in), u_rate = -k y_in.
* ``HtSteps``: r = r0 + dr * (number of the times t1, t2 passed), next_event_time.

Closed loop x' = k (r - x). The master's Gauss-Seidel sweep gives u_rate = -k u, so one
step is x <- x + k (r - x)(h - k h^2 / 2): an independent recurrence the tests compare with.
"""
from __future__ import annotations

import math
import textwrap
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

import numpy as np
import pytest

from harness.cosim.master import (AlgebraicLoopError, CoSimulation, CoSimulationError, FMUError,
                            simulate)
from harness.cosim.system import Component, Connection, Source, System

COMMON = """
import math
from pythonfmu import Fmi2Slave, Fmi2Causality, Fmi2Variability, Real, Integer

def _param(slave, name):
    slave.register_variable(Real(name, causality=Fmi2Causality.parameter,
                                 variability=Fmi2Variability.tunable))

def _out(slave, name, kind=Real):
    slave.register_variable(kind(name, causality=Fmi2Causality.output))

def _in(slave, name):
    slave.register_variable(Real(name, causality=Fmi2Causality.input))
"""

INTEGRATOR = COMMON + """
class HtIntegrator(Fmi2Slave):
    def __init__(self, **kw):
        super().__init__(**kw)
        self.x0 = 0.0; self.level = 1.0; self.fail_at = 1e300
        self.u = 0.0; self.u_rate = 0.0
        self.x = 0.0
        self.switch_count = 0; self.t_last_switch = -1e300; self.mode = 0
        for n in ("x0", "level", "fail_at"):
            _param(self, n)
        _in(self, "u"); _in(self, "u_rate")
        _out(self, "x")
        self.register_variable(Real("y", causality=Fmi2Causality.output, getter=lambda: self.u))
        for n in ("switch_count", "mode"):
            self.register_variable(Integer(n, causality=Fmi2Causality.output,
                                           variability=Fmi2Variability.discrete))
        _out(self, "t_last_switch")

    def exit_initialization_mode(self):
        if not self.level > 0:
            raise ValueError(f"invalid parameter 'level' = {self.level}: expected > 0")
        self.x = self.x0
        self.mode = int(math.floor(self.x / self.level + 1e-12))

    def do_step(self, t, h):
        if t + h > self.fail_at:
            raise RuntimeError(f"integrator failure requested at t = {self.fail_at}")
        a, b = 0.5 * self.u_rate, self.u
        x_end = self.x + b * h + a * h * h
        k_end = int(math.floor(x_end / self.level + 1e-12))
        for k in range(self.mode + 1, k_end + 1):  # upward crossings, located exactly
            c = self.x - k * self.level
            if abs(a) < 1e-300:
                tau = -c / b
            else:
                disc = max(b * b - 4 * a * c, 0.0)
                q = -0.5 * (b + math.copysign(math.sqrt(disc), b))
                roots = [r for r in (q / a, c / q if q != 0 else math.inf) if 0 <= r <= h * (1 + 1e-9)]
                tau = min(roots) if roots else h
            self.switch_count += 1
            self.t_last_switch = t + min(tau, h)
        self.mode = max(self.mode, k_end)
        self.x = x_end
        return True

    def _get_fmu_state(self):
        return {k: getattr(self, k) for k in ("x", "u", "u_rate", "switch_count", "t_last_switch", "mode")}

    def _set_fmu_state(self, state):
        for k, v in state.items():
            setattr(self, k, v)
"""

GAIN = COMMON + """
class HtGain(Fmi2Slave):
    def __init__(self, **kw):
        super().__init__(**kw)
        self.k = 1.0; self.r = 0.0; self.x_in = 0.0; self.y_in = 0.0
        _param(self, "k"); _in(self, "r"); _in(self, "x_in"); _in(self, "y_in")
        self.register_variable(Real("u", causality=Fmi2Causality.output,
                                    getter=lambda: self.k * (self.r - self.x_in)))
        self.register_variable(Real("u_rate", causality=Fmi2Causality.output,
                                    getter=lambda: -self.k * self.y_in))

    def do_step(self, t, h):
        return True
"""

STEPS = COMMON + """
class HtSteps(Fmi2Slave):
    def __init__(self, **kw):
        super().__init__(**kw)
        self.r0 = 0.0; self.dr = 1.0; self.t1 = 1e300; self.t2 = 1e300; self.time = 0.0
        for n in ("r0", "dr", "t1", "t2"):
            _param(self, n)
        self.register_variable(Real("r", causality=Fmi2Causality.output, getter=lambda: self.r0 + self.dr * ((self.time >= self.t1) + (self.time >= self.t2))))
        self.register_variable(Real("next_event_time", causality=Fmi2Causality.output, getter=self._next))

    def _next(self):
        later = [s for s in (self.t1, self.t2) if s > self.time]
        return min(later) if later else math.inf

    def setup_experiment(self, start_time, stop_time, tolerance):
        self.time = start_time

    def do_step(self, t, h):
        self.time = t + h
        return True

    def _get_fmu_state(self):
        return {"time": self.time}

    def _set_fmu_state(self, state):
        self.time = state["time"]
"""


def _build(tmp: Path, module: str, source: str, deps: dict[str, list[str]] | None) -> Path:
    """Build a pythonfmu FMU and declare the output dependencies ``deps`` (None: keep none)."""
    from pythonfmu.builder import FmuBuilder

    script = tmp / f"{module}.py"
    script.write_text(textwrap.dedent(source))
    fmu = FmuBuilder.build_FMU(script, dest=tmp, canGetAndSetFMUstate=True)
    if deps is None:
        return fmu
    with zipfile.ZipFile(fmu) as zf:
        members = {n: zf.read(n) for n in zf.namelist()}
    root = ET.fromstring(members["modelDescription.xml"])
    names = [v.get("name") for v in root.find("ModelVariables")]
    for unknown in root.find("ModelStructure").find("Outputs"):
        name = names[int(unknown.get("index")) - 1]
        unknown.set("dependencies", " ".join(str(names.index(d) + 1) for d in deps.get(name, [])))
    members["modelDescription.xml"] = ET.tostring(root, xml_declaration=True, encoding="UTF-8")
    with zipfile.ZipFile(fmu, "w") as zf:
        for name, data in members.items():
            zf.writestr(name, data)
    return fmu


@pytest.fixture(scope="module")
def slaves(tmp_path_factory) -> dict[str, Path]:
    tmp = tmp_path_factory.mktemp("master_slaves")
    return {
        "integrator": _build(tmp, "ht_integrator", INTEGRATOR, {"y": ["u"]}),
        "gain": _build(tmp, "ht_gain", GAIN, {"u": ["r", "x_in"], "u_rate": ["y_in"]}),
        "steps": _build(tmp, "ht_steps", STEPS, {}),
        "integrator_nodeps": _build(tmp_path_factory.mktemp("nodeps"), "ht_integrator_nodeps",
                                    INTEGRATOR.replace("HtIntegrator", "HtIntegratorNoDeps"), None),
    }


LOOP = (Connection("plant.x", "ctrl.x_in"), Connection("ctrl.u", "plant.u"),
        Connection("plant.y", "ctrl.y_in"), Connection("ctrl.u_rate", "plant.u_rate"))
PROBES = {"x": "plant.x", "u": "ctrl.u", "u_rate": "ctrl.u_rate", "r": "ref.r",
          "count": "plant.switch_count", "mode": "plant.mode"}


def _system(slaves, k=20.0, x0=0.0, level=1e6, r0=1.0, dr=0.5, t1=0.0105, t2=0.0337,
            fail_at=1e300, plant="integrator") -> System:
    return System(
        components=(Component("plant", slaves[plant], {"x0": x0, "level": level, "fail_at": fail_at}),
                    Component("ctrl", slaves["gain"], {"k": k}),
                    Component("ref", slaves["steps"], {"r0": r0, "dr": dr, "t1": t1, "t2": t2})),
        connections=LOOP + (Connection("ref.r", "ctrl.r"),),
        probes=PROBES)


def _recurrence(x0, k, r_of_t, points):
    """x at the given communication points by the exact FOH-step recurrence."""
    x = [x0]
    for t0, t1 in zip(points[:-1], points[1:]):
        h = t1 - t0
        x.append(x[-1] + k * (r_of_t(t0) - x[-1]) * (h - 0.5 * k * h * h))
    return np.array(x)


def test_gauss_seidel_order_follows_declared_dependencies(slaves):
    with CoSimulation(_system(slaves), 0.0, 0.01) as sim:
        order = sim.propagation_order
    pos = {name: i for i, name in enumerate(order)}
    chain = ["plant.x", "ctrl.x_in", "ctrl.u", "plant.u", "plant.y", "ctrl.y_in",
             "ctrl.u_rate", "plant.u_rate"]
    assert [pos[n] for n in chain] == sorted(pos[n] for n in chain)
    assert pos["ref.r"] < pos["ctrl.r"] < pos["ctrl.u"]


def test_closed_loop_matches_foh_recurrence_and_exact_solution(slaves):
    k, r0, h = 20.0, 1.0, 1e-3
    res = simulate(_system(slaves, k=k, r0=r0, t1=1e300, t2=1e300), 0.0, 0.2, h)
    assert np.all(res.side == 0)
    np.testing.assert_allclose(np.diff(res.time), h, rtol=1e-9)
    expected = _recurrence(0.0, k, lambda t: r0, res.time)
    np.testing.assert_allclose(res.values["x"], expected, rtol=0, atol=1e-13)
    # The FOH scheme is second order: close to the exact exponential.
    exact = r0 * (1.0 - np.exp(-k * res.time))
    assert np.max(np.abs(res.values["x"] - exact)) < 5e-5
    # u_rate propagated after y: it equals -k u at every point (not a stale value).
    np.testing.assert_allclose(res.values["u_rate"], -k * res.values["u"], rtol=1e-12)


def test_time_events_give_left_and_right_rows(slaves):
    k, r0, dr, t1, t2 = 20.0, 1.0, 0.5, 0.0105, 0.0337
    res = simulate(_system(slaves, k=k, r0=r0, dr=dr, t1=t1, t2=t2), 0.0, 0.05, 1e-3)
    assert res.time_events == pytest.approx([t1, t2], abs=1e-15)
    for te in (t1, t2):
        rows = np.flatnonzero(np.abs(res.time - te) < 1e-15)
        assert list(res.side[rows]) == [-1, 1]
        left, right = rows
        assert res.values["x"][left] == res.values["x"][right]  # state is continuous
        assert res.values["u"][right] - res.values["u"][left] == pytest.approx(k * dr, rel=1e-9)
    # Away from events the points stay on the 1 ms grid.
    ordinary = res.time[res.side == 0]
    np.testing.assert_allclose(ordinary, np.round(ordinary / 1e-3) * 1e-3, atol=1e-15)
    # And the trajectory is the recurrence with the step reference.
    points = res.time[res.side >= 0]
    r_of_t = lambda t: r0 + dr * (int(t >= t1) + int(t >= t2))
    x = res.values["x"][res.side >= 0]
    np.testing.assert_allclose(x, _recurrence(0.0, k, r_of_t, points), atol=1e-13)


def test_rollback_lands_a_point_on_every_switch(slaves):
    level = 0.07
    res = simulate(_system(slaves, level=level, t1=1e300, t2=1e300), 0.0, 0.15, 1e-3)
    x = res.values["x"]
    crossings = int(math.floor(x[-1] / level + 1e-12))
    assert len(res.switches) == crossings > 5
    assert res.stats["rollbacks"] >= crossings
    for n, sw in enumerate(res.switches, start=1):
        assert sw.located and sw.count == n
        assert (sw.before, sw.after) == (n - 1, n)
        rows = np.flatnonzero(np.abs(res.time - sw.time) <= 1e-9)
        assert list(res.side[rows]) == [-1, 1]
        # The point lies on the crossing: x equals the level there.
        assert x[rows[0]] == pytest.approx(n * level, abs=1e-12)
    # Rolling back restored every FMU: the trajectory is still the recurrence.
    points = res.time[res.side >= 0]
    np.testing.assert_allclose(x[res.side >= 0], _recurrence(0.0, 20.0, lambda t: 1.0, points),
                               atol=1e-13)


def test_two_switches_in_one_step_are_separated(slaves):
    # x' ~ 20 at the start: crossings every 0.4 ms, two per 1 ms step.
    level = 0.008
    res = simulate(_system(slaves, level=level, t1=1e300, t2=1e300), 0.0, 0.006, 1e-3)
    n = int(math.floor(res.values["x"][-1] / level + 1e-12))
    assert len(res.switches) == n >= 12
    for i, sw in enumerate(res.switches, start=1):
        row = np.flatnonzero(np.abs(res.time - sw.time) <= 1e-9)[0]
        assert res.values["x"][row] == pytest.approx(i * level, abs=1e-12)


def test_external_sources_drive_inputs(slaves):
    k = 20.0
    r_of_t = lambda t: 1.0 + math.sin(50.0 * t)
    system = System(
        components=(Component("plant", slaves["integrator"], {"level": 1e6}),
                    Component("ctrl", slaves["gain"], {"k": k})),
        connections=LOOP, sources=(Source("ctrl.r", r_of_t),),
        probes={"x": "plant.x", "u": "ctrl.u"})
    res = simulate(system, 0.0, 0.05, 1e-3)
    r = np.array([r_of_t(t) for t in res.time])
    np.testing.assert_allclose(res.values["u"], k * (r - res.values["x"]), rtol=1e-12)
    np.testing.assert_allclose(res.values["x"], _recurrence(0.0, k, r_of_t, res.time), atol=1e-13)


def test_algebraic_loop_is_reported(slaves):
    system = System(
        components=(Component("plant", slaves["integrator"]), Component("ctrl", slaves["gain"])),
        connections=(Connection("plant.y", "ctrl.x_in"), Connection("ctrl.u", "plant.u")))
    with pytest.raises(AlgebraicLoopError) as err:
        with CoSimulation(system, 0.0, 1.0):
            pass
    assert "plant.y" in str(err.value) and "ctrl.u" in str(err.value)


def test_undeclared_dependencies_mean_feedthrough(slaves):
    # pythonfmu's own description declares no dependencies: every output then depends on
    # every input, and the ABU-like loop becomes algebraic.
    with pytest.raises(AlgebraicLoopError):
        with CoSimulation(_system(slaves, plant="integrator_nodeps"), 0.0, 1.0):
            pass


def test_fmu_error_names_component_and_message_and_frees(slaves):
    calls: list[str] = []
    with pytest.raises(FMUError) as err:
        with CoSimulation(_system(slaves, fail_at=0.0125), 0.0, 0.05,
                          fmi_call_logger=calls.append) as sim:
            sim.run()
    assert err.value.component == "plant"
    assert "integrator failure requested at t = 0.0125" in str(err.value)
    # pythonfmu reports a Python exception as fmi2Fatal, after which FMI 2.0 allows no call
    # on that instance; the two others are terminated and freed.
    assert err.value.function == "fmi2DoStep" and "(fatal)" in str(err.value)
    assert sum(c.startswith("fmi2FreeInstance") for c in calls) == 2
    assert sum(c.startswith("fmi2Terminate") for c in calls) == 2
    assert sim.live_instances == [] and sim.abandoned_instances == ["plant"]

    calls.clear()
    with pytest.raises(FMUError) as err:
        with CoSimulation(_system(slaves, level=-1.0), 0.0, 0.05,
                          fmi_call_logger=calls.append) as sim:
            sim.run()
    assert err.value.component == "plant"
    assert "invalid parameter 'level' = -1.0" in str(err.value)
    assert sum(c.startswith("fmi2FreeInstance") for c in calls) == 2
    assert sim.live_instances == [] and sim.abandoned_instances == ["plant"]


def test_bad_names_are_reported(slaves, tmp_path):
    base = _system(slaves)
    bad_probe = System(base.components, base.connections, probes={"z": "plant.nonexistent"})
    with pytest.raises(CoSimulationError, match="plant.*no variable 'nonexistent'"):
        simulate(bad_probe, 0.0, 0.01)
    bad_conn = System(base.components, base.connections + (Connection("ctrl.u", "plant.x"),))
    with pytest.raises(CoSimulationError, match="causality 'output', expected input"):
        simulate(bad_conn, 0.0, 0.01)
    missing = System((Component("plant", tmp_path / "missing.fmu"),))
    with pytest.raises(CoSimulationError, match="not found"):
        simulate(missing, 0.0, 0.01)
