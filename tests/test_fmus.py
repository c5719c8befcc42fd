"""The three FMUs built by ``fmus.build``: packaging, model description, behaviour alone
under fmpy, FMU state rollback and parameter errors.

Expected values come from closed forms (constant-acceleration spin-down of the rotor, the
inclined sine of the reference, the PI integrator with a linear speed), from the FMI
standard, and from comparing two runs of the same FMU, never from the FMUs' own output.
"""
from __future__ import annotations

import ast
import json
import math
import subprocess
import sys
import textwrap
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import fmi2Error
from fmpy.simulation import instantiate_fmu
from fmpy.validation import validate_fmu

from fmus.build import FMU_NAMES, FMU_SPECS, PROJECT_PACKAGES

# Report values (sec. 3.3, 4.2) used as defaults by the FMUs.
M, D, L, MU = 1.4e-4, 3.0e-3, 1.15e-2, 2.75e-3
J_ABU = 4.5e-5
K_LEVER = (L - D / 5.0) / L
W17 = -2.0 * math.pi * 17.0
NO_EVENT = 1e30
NO_SWITCH = -1e30


# --------------------------------------------------------------------------- helpers
@pytest.fixture(scope="module")
def extracted(fmu_dir, tmp_path_factory):
    """name -> (unzip directory, model description), extracted once for this module."""
    root = tmp_path_factory.mktemp("unzipped")
    return {name: (extract(str(path), unzipdir=str(root / name)),
                   read_model_description(str(path)))
            for name, path in fmu_dir.items()}


class Slave:
    """An instantiated FMU addressed by variable names, with its log captured."""

    def __init__(self, unzipdir, md, start_time=0.0, **start_values):
        self.md = md
        self.vars = {v.name: v for v in md.modelVariables}
        self.messages: list[tuple[int, str]] = []

        def logger(_env, _instance, status, _category, message):
            self.messages.append((status, message.decode() if message else ""))

        self.fmu = instantiate_fmu(unzipdir, md, logger=logger, debug_logging=True)
        self.time = start_time
        self.fmu.setupExperiment(startTime=start_time)
        self.fmu.enterInitializationMode()
        self.set(**start_values)

    def init(self):
        self.fmu.exitInitializationMode()
        return self

    def set(self, **values):
        for name, value in values.items():
            v = self.vars[name]
            setter = {"Real": self.fmu.setReal, "Integer": self.fmu.setInteger,
                      "Boolean": self.fmu.setBoolean}[v.type]
            setter([v.valueReference], [value])

    def get(self, name):
        v = self.vars[name]
        getter = {"Real": self.fmu.getReal, "Integer": self.fmu.getInteger,
                  "Boolean": self.fmu.getBoolean}[v.type]
        return getter([v.valueReference])[0]

    def outputs(self) -> dict:
        return {name: self.get(name) for name, v in self.vars.items() if v.causality == "output"}

    def step(self, h):
        self.fmu.doStep(self.time, h)
        self.time += h

    def free(self):
        self.fmu.terminate()
        self.fmu.freeInstance()


def make(extracted, name, start_time=0.0, **start_values) -> Slave:
    unzipdir, md = extracted[name]
    return Slave(unzipdir, md, start_time, **start_values).init()


def inclined_sine(t, w0, we, t0, te):
    """Report eq. 4.8, written out independently of controller.reference."""
    s = min(max((t - t0) / te, 0.0), 1.0)
    return w0 + (we - w0) * (s - math.sin(2.0 * math.pi * s) / (2.0 * math.pi))


# --------------------------------------------------------------------------- packaging
def test_build_writes_three_self_describing_fmus(fmu_dir):
    assert set(fmu_dir) == set(FMU_NAMES) == {"AbuBall", "SpeedController", "Staircase"}
    modules, vendored_names = set(), set()
    for spec in FMU_SPECS:
        path = fmu_dir[spec.name]
        assert path.name == f"{spec.name}.fmu" and path.is_file()
        md = read_model_description(str(path))
        assert md.coSimulation.modelIdentifier == spec.name
        assert md.coSimulation.canGetAndSetFMUstate and md.coSimulation.canSerializeFMUstate
        with zipfile.ZipFile(path) as z:
            names = z.namelist()
            module = z.read("resources/slavemodule.txt").decode().strip()
            assert module == spec.module and f"resources/{module}.py" in names
            modules.add(module)
            top = {n.split("/")[1] for n in names if n.startswith("resources/") and n.count("/") > 1}
            # the project packages travel only under their vendored names
            assert not top & set(PROJECT_PACKAGES)
            for package, vendored in spec.vendored:
                assert f"resources/{vendored}/__init__.py" in names
                vendored_names.add(vendored)
            for name in names:
                if name.startswith("resources/") and name.endswith(".py") and \
                        not name.startswith("resources/pythonfmu/"):
                    tree = ast.parse(z.read(name).decode(), filename=name)
                    for node in ast.walk(tree):
                        if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                            assert node.module.split(".")[0] not in PROJECT_PACKAGES, name
                        if isinstance(node, ast.Import):
                            assert all(a.name.split(".")[0] not in PROJECT_PACKAGES
                                       for a in node.names), name
    assert len(modules) == 3 and len(vendored_names) == 5  # all unique


SELF_CONTAINED = textwrap.dedent("""
    import importlib.abc, json, math, sys
    BLOCKED = {blocked!r}
    attempts = []

    class Block(importlib.abc.MetaPathFinder):
        def find_spec(self, name, path=None, target=None):
            if name.split(".")[0] in BLOCKED:
                attempts.append(name)
                raise ModuleNotFoundError(f"blocked project package {{name}}")
            return None

    sys.meta_path.insert(0, Block())
    from fmpy import extract, read_model_description
    from fmpy.simulation import instantiate_fmu

    paths = json.loads(sys.argv[1])
    fmus, vr = {{}}, {{}}
    for name, path in paths.items():
        md = read_model_description(path)
        fmu = instantiate_fmu(extract(path), md)
        vr[name] = {{v.name: v.valueReference for v in md.modelVariables}}
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        fmus[name] = fmu

    def get(n, v): return fmus[n].getReal([vr[n][v]])[0]
    def put(n, v, x): fmus[n].setReal([vr[n][v]], [x])

    # All three in one process, closed loop by hand (Gauss-Seidel in dependency order).
    t, h, alphas = 0.0, 1e-3, []
    for k in range(20):
        put("SpeedController", "omega_ref", get("Staircase", "omega_ref"))
        for v in ("omega", "theta"):
            put("SpeedController", v, get("AbuBall", v))
        put("AbuBall", "torque", get("SpeedController", "torque"))
        put("SpeedController", "alpha", get("AbuBall", "alpha"))
        put("AbuBall", "torque_rate", get("SpeedController", "torque_rate"))
        alphas.append(get("AbuBall", "alpha"))
        for fmu in fmus.values():
            fmu.doStep(t, h)
        t += h
    print(json.dumps({{"attempts": attempts, "alpha0": alphas[0],
                      "omega": get("AbuBall", "omega"),
                      "modules": sorted(m for m in sys.modules if m.startswith(
                          ("abufmu_", "abuball_", "speedcontroller_", "staircase_")) and "." not in m)}}))
""")


def test_fmus_are_self_contained_and_coexist_in_one_process(fmu_dir, tmp_path):
    """Without the project packages importable, all three FMUs load together and run a loop."""
    script = tmp_path / "run.py"
    script.write_text(SELF_CONTAINED.format(blocked=set(PROJECT_PACKAGES)))
    paths = {name: str(path) for name, path in fmu_dir.items()}
    done = subprocess.run([sys.executable, str(script), json.dumps(paths)], cwd=tmp_path,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout.strip().splitlines()[-1])
    assert result["attempts"] == []
    assert result["modules"] == sorted([
        "abufmu_abuball", "abufmu_speedcontroller", "abufmu_staircase", "abuball_abu_model",
        "speedcontroller_abu_model", "speedcontroller_controller", "staircase_abu_model",
        "staircase_controller"] + [f"abufmu_{n}{suffix}" for n in ("abuball", "speedcontroller",
                                                                   "staircase")
                                   for suffix in ("_pythonfmu", "_rt")])
    # The first setpoint step (lead rounding: at t0 = 0, -17 Hz -> -18 Hz) makes the rotor's
    # acceleration jump by 2 zeta wn dW (integral PI on J_abu alpha = T).
    assert result["alpha0"] == pytest.approx(2 * 0.5 * 2.2 * (-2 * math.pi), rel=1e-12)
    assert result["omega"] == pytest.approx(W17 + result["alpha0"] * 0.02, abs=0.01)


# --------------------------------------------------------------------------- model description
@pytest.mark.parametrize("name", ["AbuBall", "SpeedController", "Staircase"])
def test_validate_fmu_reports_no_problem(fmu_dir, name):
    assert validate_fmu(str(fmu_dir[name])) == []


@pytest.mark.parametrize("name", ["AbuBall", "SpeedController", "Staircase"])
def test_every_variable_is_documented_with_a_unit(fmu_dir, name):
    md = read_model_description(str(fmu_dir[name]))
    units = {u.name: u for u in md.unitDefinitions}
    for v in md.modelVariables:
        assert v.description, v.name
        if v.type == "Real":
            assert v.unit in units, v.name
    assert all(v.causality in ("parameter", "input", "output") for v in md.modelVariables)
    assert all(v.variability == "fixed" for v in md.modelVariables if v.causality == "parameter")


def test_units_carry_si_base_exponents(fmu_dir):
    md = read_model_description(str(fmu_dir["AbuBall"]))
    by_name = {v.name: v.unit for v in md.modelVariables}
    assert (by_name["omega"], by_name["alpha"], by_name["torque"], by_name["torque_rate"],
            by_name["normal_force"], by_name["m"], by_name["J_abu"], by_name["mu"]) == (
        "rad/s", "rad/s2", "N.m", "N.m/s", "N", "kg", "kg.m2", "1")
    base = {u.name: u.baseUnit for u in md.unitDefinitions}
    assert (base["N.m"].kg, base["N.m"].m, base["N.m"].s) == (1, 2, -2)
    assert (base["rad/s2"].rad, base["rad/s2"].s) == (1, -2)


DECLARED = {
    "AbuBall": {"alpha": {"torque"}, "beta_ddot": {"torque"}, "friction_force": {"torque"},
                "mu_req": {"torque"}, "torque_applied": {"torque"}, "theta": set(),
                "omega": set(), "beta": set(), "beta_dot": set(), "normal_force": set(),
                "mode": set(), "switch_count": set(), "t_last_switch": set(),
                "step_switches": set(), "t_first_step_switch": set(),
                "jerk": {"torque", "torque_rate"},
                "snap": {"torque", "torque_rate", "torque_accel"},
                "crackle": {"torque", "torque_rate", "torque_accel", "torque_jerk"},
                "mu_req_peak": set()},
    "SpeedController": {"torque": {"omega_ref", "omega", "theta"},
                        "torque_rate": {"omega_ref", "omega", "alpha"}, "x_I": set(),
                        "torque_accel": {"alpha", "jerk"}, "torque_jerk": {"jerk", "snap"},
                        "torque_snap": {"snap", "crackle"}},
    "Staircase": {"omega_ref": set(), "next_event_time": set(), "step_index": set()},
}


@pytest.mark.parametrize("name", ["AbuBall", "SpeedController", "Staircase"])
def test_master_reads_true_output_dependencies(fmu_dir, name, capsys):
    import fmpy

    fmpy.dump(str(fmu_dir[name]))  # FMPy's own summary reads the whole description
    assert f"Model Name         {name}" in capsys.readouterr().out
    md = read_model_description(str(fmu_dir[name]))
    deps = {u.variable.name: {d.name for d in u.dependencies} for u in md.outputs}
    assert deps == DECLARED[name]
    outputs = {v.name for v in md.modelVariables if v.causality == "output"}
    # FMI 2.0: outputs with initial="calculated" are initial unknowns (ascending indices).
    assert {u.variable.name for u in md.initialUnknowns} == outputs
    order = [md.modelVariables.index(u.variable) for u in md.initialUnknowns]
    assert order == sorted(order)


@pytest.mark.parametrize("name, perturb, scenarios", [
    # the ball stuck, then slipping: friction feeds through in stick, beta_ddot in slip
    # (with a motor lag the jerk depends on the torque too)
    ("AbuBall", {"torque": 3e-4, "torque_rate": 1e-3},
     [{}, {"beta_dot0": 1.0}, {"tau_motor": 0.01}]),
    ("SpeedController", {"omega_ref": -110.0, "omega": -100.0, "theta": 2.0, "alpha": 5.0},
     [{"theta_ref_mode": 1}]),  # the thesis mode uses theta
])
def test_declared_dependencies_match_behaviour(extracted, name, perturb, scenarios):
    """An input changed at a communication point changes exactly the outputs that declare it."""
    changed = {inp: set() for inp in perturb}
    for start in scenarios:
        slave = make(extracted, name, **start)
        slave.step(0.01)
        for inp, value in perturb.items():
            before = slave.outputs()
            slave.set(**{inp: value})
            after = slave.outputs()
            changed[inp] |= {k for k in before if before[k] != after[k]}
        slave.free()
    for inp in perturb:
        assert changed[inp] == {k for k, deps in DECLARED[name].items() if inp in deps}, inp


# --------------------------------------------------------------------------- each FMU alone
def test_staircase_alone_produces_the_staircase_of_the_inclined_sine(fmu_dir):
    w0, we, t0, te, step = -2 * math.pi * 17, -2 * math.pi * 22, 0.105, 1.0, 2 * math.pi
    result = simulate_fmu(str(fmu_dir["Staircase"]), start_time=0.0, stop_time=1.3,
                          output_interval=0.01,
                          start_values={"omega0": w0, "omega_end": we, "t0": t0, "te": te})
    n = 5
    for t, omega_ref, next_event, index in zip(result["time"], result["omega_ref"],
                                               result["next_event_time"], result["step_index"]):
        progress = abs(inclined_sine(t, w0, we, t0, te) - w0) / step
        # lead rounding: step k when the sine has reached w0 + (k - 1) step, the first at t0
        expected = 0 if t < t0 else min(n, math.floor(progress + 1e-12) + 1)
        assert index == expected and omega_ref == pytest.approx(w0 - expected * step, abs=1e-9)
        if expected < n:
            # the next event is where the sine reaches the next level
            reached = abs(inclined_sine(next_event, w0, we, t0, te) - w0)
            assert next_event > t and reached == pytest.approx(expected * step, abs=1e-9)
        else:
            assert next_event == NO_EVENT


def test_staircase_lands_on_steps_right_continuously(extracted):
    slave = make(extracted, "Staircase", start_time=0.0, t0=0.2)
    assert slave.get("omega_ref") == W17 and slave.get("next_event_time") == 0.2
    levels = []
    for _ in range(5):
        t_next = slave.get("next_event_time")
        slave.step(t_next - slave.time)  # t + (t_s - t) may round one ulp short of t_s
        levels.append(slave.get("omega_ref"))
        assert slave.get("next_event_time") > t_next  # already past the step just taken
    assert levels == pytest.approx([W17 - k * 2 * math.pi for k in range(1, 6)], abs=1e-12)
    assert slave.get("next_event_time") == NO_EVENT
    slave.free()


def test_speed_controller_alone_with_constant_inputs(fmu_dir):
    w_ref, w = -110.0, -100.0
    result = simulate_fmu(str(fmu_dir["SpeedController"]), stop_time=1.0, output_interval=0.1,
                          start_values={"omega_ref": w_ref, "omega": w})
    zeta, wn = 0.5, 2.2
    kp, ki = 2 * zeta * wn * J_ABU, wn**2 * J_ABU
    t = result["time"]
    assert np.allclose(result["x_I"], (w_ref - w) * t, rtol=1e-12, atol=1e-12)
    assert np.allclose(result["torque"], kp * (w_ref - w) + ki * (w_ref - w) * t, rtol=1e-12)
    assert np.allclose(result["torque_rate"], ki * (w_ref - w), rtol=1e-12)


@pytest.mark.parametrize("h", [0.05, 0.2])
def test_speed_controller_integrator_is_exact_for_a_linear_speed(extracted, h):
    """x_I advances with omega(tau) = omega + alpha tau: exact whatever the step size."""
    w_ref, w0, alpha = -110.0, -100.0, -7.0
    slave = make(extracted, "SpeedController", omega_ref=w_ref)
    for _ in range(round(1.0 / h)):
        slave.set(omega=w0 + alpha * slave.time, alpha=alpha)
        slave.step(h)
    t = slave.time
    assert slave.get("x_I") == pytest.approx((w_ref - w0) * t - 0.5 * alpha * t * t, rel=1e-12)
    slave.free()


def test_speed_controller_thesis_mode_uses_t_times_omega_ref(extracted):
    slave = make(extracted, "SpeedController", theta_ref_mode=1)
    slave.step(0.5)
    slave.set(omega_ref=-110.0, omega=-100.0, theta=-48.0)
    kp, ki = 2 * 0.5 * 2.2 * J_ABU, 2.2**2 * J_ABU
    assert slave.get("torque") == pytest.approx(kp * -10.0 + ki * (0.5 * -110.0 + 48.0), rel=1e-12)
    slave.free()


def test_abu_ball_alone_spins_down_and_slips_where_the_stick_test_fails(fmu_dir):
    """Constant decelerating torque from -17 Hz: the ball sticks until (l - d/5)|alpha| = mu l omega^2."""
    torque = 1e-3
    result = simulate_fmu(str(fmu_dir["AbuBall"]), stop_time=1.0, output_interval=0.01,
                          start_values={"torque": torque},
                          output=["omega", "alpha", "mu_req", "mode", "switch_count",
                                  "t_last_switch", "beta_dot"])
    alpha = torque / J_ABU
    t_slip = (abs(W17) - math.sqrt(K_LEVER * alpha / MU)) / alpha  # closed form, stick phase
    assert np.allclose(result["alpha"], alpha, rtol=1e-12)
    stuck = result["time"] < t_slip
    assert np.all(result["mode"][stuck] == 0) and np.all(result["mu_req"][stuck] <= MU)
    assert np.all(result["beta_dot"][stuck] == 0.0)
    assert np.all(result["mode"][~stuck] == -1)  # slips backwards, as -sign(alpha)
    assert np.all(result["beta_dot"][~stuck] < 0.0)
    assert result["switch_count"][-1] == 1
    assert result["t_last_switch"][-1] == pytest.approx(t_slip, abs=1e-10)
    # at the slip instant the stick test is tight
    omega_slip = W17 + alpha * t_slip
    assert (L - D / 5) * alpha == pytest.approx(MU * L * omega_slip**2, rel=1e-9)
    assert result["t_last_switch"][0] == NO_SWITCH


def test_abu_ball_outputs_are_right_hand_limits_after_an_input_jump(extracted):
    slave = make(extracted, "AbuBall", torque=-2e-4)
    slave.step(0.1)
    theta = slave.get("theta")
    slave.set(torque=5e-4)  # a jump at the communication point, no step taken
    assert slave.get("alpha") == 5e-4 / J_ABU
    assert slave.get("friction_force") == pytest.approx(-M * (L - D / 5) * 5e-4 / J_ABU, rel=1e-12)
    omega = slave.get("omega")
    assert slave.get("mu_req") == pytest.approx(K_LEVER * 5e-4 / J_ABU / omega**2, rel=1e-12)
    assert slave.get("theta") == theta
    slave.free()


def test_abu_ball_torque_rate_is_a_first_order_hold(extracted):
    """With T(tau) = T0 + r tau in stick: omega gains T0 h/J + r h^2/(2J) in one step."""
    t0_, rate, h = 2e-4, -3e-3, 0.05
    slave = make(extracted, "AbuBall", torque=t0_, torque_rate=rate)
    slave.step(h)
    assert slave.get("mode") == 0
    assert slave.get("omega") == pytest.approx(W17 + (t0_ * h + 0.5 * rate * h * h) / J_ABU, rel=1e-13)
    assert slave.get("theta") == pytest.approx(W17 * h + (t0_ * h**2 / 2 + rate * h**3 / 6) / J_ABU,
                                               rel=1e-12)
    slave.free()


# --------------------------------------------------------------------------- FMU state
def _abu_ball_window(slave):
    """From t = 0.8 s: decelerating torque until 0.9 s (stick -> slip), then none (slip -> stick)."""
    record = []
    for k in range(10):
        slave.set(torque=1e-3 if k < 5 else 0.0, torque_rate=-1e-3 if k < 5 else 0.0)
        slave.step(0.02)
        record.append(slave.outputs())
    return record


def test_abu_ball_state_rollback_is_bit_identical_through_stick_slip_stick(extracted):
    slave = make(extracted, "AbuBall", torque=1e-3)
    for _ in range(8):
        slave.step(0.1)
    state = slave.fmu.getFMUstate()
    time = slave.time
    first = _abu_ball_window(slave)
    assert [r["switch_count"] for r in (first[0], first[-1])] == [0, 2]
    assert {r["mode"] for r in first} == {0, -1}
    slave.fmu.setFMUstate(state)
    slave.time = time
    assert _abu_ball_window(slave) == first  # exact float equality
    # a serialised state (JSON inside) restores the same trajectory
    restored = slave.fmu.deSerializeFMUstate(slave.fmu.serializeFMUstate(state))
    slave.fmu.setFMUstate(restored)
    slave.time = time
    assert _abu_ball_window(slave) == first
    # the saved state was not altered by running on (it is a snapshot, not a view)
    slave.fmu.setFMUstate(state)
    slave.time = time
    assert _abu_ball_window(slave) == first
    slave.fmu.freeFMUstate(state)
    slave.free()


def test_abu_ball_rollback_restores_switch_bookkeeping(extracted):
    slave = make(extracted, "AbuBall", torque=1e-3)
    slave.step(0.8)
    state = slave.fmu.getFMUstate()
    slave.step(0.2)  # the stick -> slip switch happens inside this step
    assert slave.get("step_switches") == 1
    t_switch = slave.get("t_first_step_switch")
    slave.fmu.setFMUstate(state)
    slave.time = 0.8
    assert (slave.get("switch_count"), slave.get("step_switches"), slave.get("mode")) == (0, 0, 0)
    slave.step(t_switch - 0.8)  # the master lands a communication point on the switch
    assert slave.get("mode") == -1 and slave.get("t_last_switch") == pytest.approx(t_switch, abs=1e-12)
    slave.free()


def test_speed_controller_and_staircase_rollback_is_bit_identical(extracted):
    ctrl = make(extracted, "SpeedController", omega_ref=-110.0, omega=-100.0)
    stairs = make(extracted, "Staircase")
    for _ in range(3):
        ctrl.step(0.1), stairs.step(0.1)
    states = ctrl.fmu.getFMUstate(), stairs.fmu.getFMUstate()
    time = ctrl.time

    def run():
        out = []
        for k in range(6):
            ctrl.set(omega=-100.0 + k, alpha=3.0 * k, theta=-k)
            ctrl.step(0.1), stairs.step(0.1)
            out.append((ctrl.outputs(), stairs.outputs()))
        return out

    first = run()
    assert first[0][1]["omega_ref"] != first[-1][1]["omega_ref"]  # steps happened
    for slave, state in zip((ctrl, stairs), states):
        slave.fmu.setFMUstate(state)
        slave.time = time
    assert run() == first
    ctrl.free(), stairs.free()


def test_mu_req_peak_is_the_maximum_inside_the_step_and_travels_with_the_state(extracted):
    """alpha = K t from rest at omega0 (torque ramp, first-order hold): mu_req = k K t /
    (w0 + K t^2/2)^2 peaks at t* = sqrt(2 w0 / (3 K)) inside the step (closed form); the
    output is that peak, the saved FMU state restores it after a further step."""
    from abu_model.params import BallParams, PlantParams

    params = PlantParams(ball=BallParams(mu=0.03))
    w0, K, h = 100.0, 3000.0, 0.5
    k, J = params.ball.lever_ratio, params.J_total
    t_star = math.sqrt(2.0 * w0 / (3.0 * K))
    peak = k * K * t_star / (w0 + K * t_star**2 / 2.0) ** 2
    slave = make(extracted, "AbuBall", omega0=w0, mu=0.03)
    assert slave.get("mu_req_peak") == 0.0  # no step yet
    slave.set(torque=0.0, torque_rate=J * K)
    slave.step(h)
    assert slave.get("mode") == 0 and slave.get("step_switches") == 0
    assert slave.get("mu_req_peak") == pytest.approx(peak, rel=1e-12)
    assert slave.get("mu_req") < peak * (1 - 1e-3)  # the end point alone misses it
    state = slave.fmu.getFMUstate()
    slave.set(torque=J * K * h, torque_rate=0.0)  # constant torque: mu_req falls
    slave.step(h)
    assert slave.get("mu_req_peak") < peak * (1 - 1e-3)
    slave.fmu.setFMUstate(state)
    assert slave.get("mu_req_peak") == pytest.approx(peak, rel=1e-12)
    slave.fmu.freeFMUstate(state)
    slave.free()


# --------------------------------------------------------------------------- bad parameters
@pytest.mark.parametrize("name, values, parameter", [
    ("AbuBall", {"m": -1.4e-4}, "m"),
    ("AbuBall", {"d": 0.03}, "d"),          # d >= 2 l: no ball fits
    ("AbuBall", {"mu": -0.1}, "mu"),
    ("AbuBall", {"omega0": math.nan}, "omega0"),
    ("AbuBall", {"J_abu": math.inf}, "J_abu"),
    ("AbuBall", {"mu_d": 0.5}, "mu_d"),       # sliding above static friction
    ("SpeedController", {"zeta": -0.5}, "zeta"),
    ("SpeedController", {"theta_ref_mode": 3}, "theta_ref_mode"),
    ("Staircase", {"te": 0.0}, "te"),
    ("Staircase", {"omega_end": -2 * math.pi * 17.5}, "omega_end"),  # no whole step
    ("Staircase", {"rounding": 5}, "rounding"),
])
def test_bad_parameter_fails_initialization_with_a_logged_message(extracted, name, values, parameter):
    """A bad parameter is a recoverable fmi2Error naming it: a non-finite value at fmi2SetReal,
    an out-of-range one at fmi2ExitInitializationMode (which can be called again once fixed)."""
    unzipdir, md = extracted[name]
    finite = all(math.isfinite(v) for v in values.values())
    with pytest.raises(FMICallException) as info:
        slave = Slave(unzipdir, md)
        slave.set(**values)
        slave.fmu.exitInitializationMode()
    assert info.value.status == fmi2Error  # recoverable, not fmi2Fatal
    errors = [msg for status, msg in slave.messages if status == fmi2Error]
    expected = f"invalid parameter '{parameter}'" if finite else f"'{parameter}' = {values[parameter]}"
    assert any(expected in msg and name in msg for msg in errors), slave.messages
    if finite:  # recover: restore the default and initialize the same instance
        default = next(v.start for v in md.modelVariables if v.name == parameter)
        slave.set(**{parameter: type(values[parameter])(default)})
        slave.fmu.exitInitializationMode()
        slave.step(0.01)
    slave.free()


@pytest.mark.parametrize("name, inp", [("AbuBall", "torque_jerk"), ("AbuBall", "torque_snap"),
                                       ("SpeedController", "snap"),
                                       ("SpeedController", "crackle")])
@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_a_non_finite_hold_input_is_an_fmi2error_naming_it(extracted, name, inp, bad):
    """The Taylor hold's higher inputs: a non-finite value is refused at fmi2SetReal with
    fmi2Error and a logged message naming the input; the instance keeps its last value and
    steps on."""
    slave = make(extracted, name)
    slave.set(**{inp: 1.0})
    with pytest.raises(FMICallException) as info:
        slave.set(**{inp: bad})
    assert info.value.status == fmi2Error
    errors = [msg for status, msg in slave.messages if status == fmi2Error]
    assert any(f"'{inp}' = {bad!r}" in msg and name in msg for msg in errors), slave.messages
    assert slave.get(inp) == 1.0
    slave.step(1e-3)
    assert all(math.isfinite(v) for v in slave.outputs().values() if isinstance(v, float))
    slave.free()


FREE_AFTER_FAILURE = textwrap.dedent("""
    import gc, json, sys
    from fmpy import extract, read_model_description
    from fmpy.simulation import instantiate_fmu

    bad = {"AbuBall": ("m", -1.0), "SpeedController": ("omega_n", 0.0), "Staircase": ("te", -1.0)}
    for name, path in json.loads(sys.argv[1]).items():
        md = read_model_description(path)
        unzipdir = extract(path)
        vr = {v.name: v.valueReference for v in md.modelVariables}
        for _ in range(5):
            fmu = instantiate_fmu(unzipdir, md)
            fmu.setupExperiment(startTime=0.0)
            fmu.enterInitializationMode()
            fmu.setReal([vr[bad[name][0]]], [bad[name][1]])
            try:
                fmu.exitInitializationMode()
            except Exception:
                pass
            else:
                raise SystemExit(f"{name}: bad parameter accepted")
            fmu.terminate()  # not allowed after fmi2Fatal by FMI 2.0, but masters do it
            fmu.freeInstance()
            gc.collect()
        fmu = instantiate_fmu(unzipdir, md)  # a healthy instance still works
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        fmu.doStep(0.0, 0.1)
        fmu.terminate()
        fmu.freeInstance()
    print("survived")
""")


def test_freeing_an_instance_that_failed_initialization_does_not_crash(fmu_dir, tmp_path):
    """pythonfmu 0.7 releases the slave twice after an exception; the slaves guard against it."""
    script = tmp_path / "free.py"
    script.write_text(FREE_AFTER_FAILURE)
    paths = {name: str(path) for name, path in fmu_dir.items()}
    done = subprocess.run([sys.executable, str(script), json.dumps(paths)], cwd=tmp_path,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, (done.returncode, done.stderr[-2000:])
    assert done.stdout.strip().endswith("survived")


def test_start_values_round_trip_exactly(fmu_dir):
    md = read_model_description(str(fmu_dir["Staircase"]))
    starts = {v.name: v.start for v in md.modelVariables}
    assert float(starts["omega0"]) == -2 * math.pi * 17 and float(starts["step"]) == 2 * math.pi
    md = read_model_description(str(fmu_dir["AbuBall"]))
    assert float({v.name: v.start for v in md.modelVariables}["omega0"]) == W17


@pytest.mark.parametrize("name", ["AbuBall", "SpeedController", "Staircase"])
def test_docs_variable_tables_match_the_built_fmus(fmu_dir, name):
    from fmus.model_description import variable_table_markdown

    doc = (Path(__file__).resolve().parents[1] / "docs" / "fmus.md").read_text(encoding="utf-8")
    start = doc.index(f"<!-- table:{name} -->\n") + len(f"<!-- table:{name} -->\n")
    table = doc[start:doc.index("<!-- end table -->", start)]
    with zipfile.ZipFile(fmu_dir[name]) as z:
        assert table == variable_table_markdown(z.read("modelDescription.xml"))
