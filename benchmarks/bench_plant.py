"""Standard-library plant vs the numpy/scipy plant it replaced: same results, faster steps.

Run: ``nice python benchmarks/bench_plant.py [n_cases]``.

Family (seeded): mu in [1e-3, 5e-2] (log-uniform), mu_d = mu or in [0.5 mu, mu], omega0 in
-[8, 30] Hz, a torque that ramps (jerk 50-3000 rad/s^3 times J) with setpoint-like jumps
every 0.1-0.3 s (so the ball slips, re-sticks and sometimes slips back), 1 ms steps over
1.5 s; a quarter of the cases with a motor lag (tau_motor 1-20 ms), a quarter with the
ball's reaction on the rotor, some starting in slip. Both plants get the same inputs; the
script prints the largest differences of switch times [s] and of the final states
(relative), and the time per step of each, measured alternately (median of pair ratios).
"""
from __future__ import annotations

import math
import random
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from abu_model.params import BallParams, PlantParams  # noqa: E402
from abu_model.plant import AbuPlant  # noqa: E402
import plant_scipy_legacy as legacy  # noqa: E402

HZ = 2.0 * math.pi


def make_case(seed: int) -> tuple[PlantParams, dict, list[tuple[float, float, float]]]:
    """Plant parameters, initial state and the (h, torque, rate) inputs of one case."""
    rng = random.Random(seed)
    mu = math.exp(rng.uniform(math.log(1e-3), math.log(5e-2)))
    mu_d = None if rng.random() < 0.6 else mu * rng.uniform(0.5, 1.0)
    kind = rng.randrange(4)
    params = PlantParams(ball=BallParams(mu=mu, mu_d=mu_d),
                         tau_motor=rng.uniform(1e-3, 2e-2) if kind == 1 else 0.0,
                         ball_reaction=kind == 2)
    omega0 = -rng.uniform(8.0, 30.0) * HZ
    init = dict(omega0=omega0, beta_dot0=rng.choice([0.0, 0.0, 0.0, 0.5, -0.5]))
    J = params.J_total
    jerk = rng.uniform(50.0, 3000.0) * rng.choice([-1.0, 1.0])
    h, t, level = 1e-3, 0.0, 0.0
    next_jump = rng.uniform(0.1, 0.3)
    inputs = []
    for _ in range(1500):
        if t >= next_jump:
            level += J * rng.uniform(-40.0, 40.0)
            next_jump += rng.uniform(0.1, 0.3)
        inputs.append((h, level + J * jerk * t * 0.1, J * jerk * 0.1))
        t += h
    return params, init, inputs


def run(plant_cls, params, init, inputs):
    plant = plant_cls(params, **init)
    switches = []
    start = time.perf_counter()
    for h, torque, rate in inputs:
        switches += plant.advance(h, torque, rate)
    return time.perf_counter() - start, switches, plant.state


def main(n_cases: int = 40) -> None:
    worst_switch, worst_state, ratios, new_us, old_us, n_switches = 0.0, 0.0, [], [], [], 0
    mismatched = 0
    for seed in range(n_cases):
        params, init, inputs = make_case(seed)
        t_new, sw_new, st_new = run(AbuPlant, params, init, inputs)
        t_old, sw_old, st_old = run(legacy.AbuPlant, params, init, inputs)
        t_new2, _, _ = run(AbuPlant, params, init, inputs)  # alternate: new, old, new
        t_new = min(t_new, t_new2)
        ratios.append(t_old / t_new)
        new_us.append(1e6 * t_new / len(inputs))
        old_us.append(1e6 * t_old / len(inputs))
        n_switches += len(sw_new)
        if [(s.from_mode, s.to_mode) for s in sw_new] != [(s.from_mode, s.to_mode) for s in sw_old]:
            mismatched += 1
            print(f"seed {seed}: switch sequences differ: {sw_new} vs {sw_old}")
            continue
        for a, b in zip(sw_new, sw_old):
            worst_switch = max(worst_switch, abs(a.time - b.time))
        for name in ("theta", "omega", "beta", "beta_dot", "torque_applied"):
            x, y = getattr(st_new, name), getattr(st_old, name)
            scale = max(abs(y), 1e-9 if name != "torque_applied" else 1e-12)
            worst_state = max(worst_state, abs(x - y) / scale)
    print(f"family: {n_cases} seeded cases x 1500 steps of 1 ms (see module docstring); "
          f"{n_switches} switches in all")
    print(f"switch sequences that differ: {mismatched}")
    print(f"largest switch-time difference: {worst_switch:.3e} s")
    print(f"largest final-state difference (relative): {worst_state:.3e}")
    print(f"time per step: stdlib {statistics.median(new_us):.1f} us, numpy/scipy "
          f"{statistics.median(old_us):.1f} us (medians); median ratio old/new = "
          f"{statistics.median(ratios):.2f}x")
    stick = make_case(0)[0]
    plant_new = AbuPlant(stick, omega0=-20 * HZ)
    plant_old = legacy.AbuPlant(stick, omega0=-20 * HZ)
    pairs = []
    for _ in range(7):  # pure stick steps, no switch: the common step of a staircase run
        a = time.perf_counter()
        for _ in range(2000):
            plant_new.advance(1e-3, 1e-5, 0.0)
        b = time.perf_counter()
        for _ in range(2000):
            plant_old.advance(1e-3, 1e-5, 0.0)
        c = time.perf_counter()
        pairs.append(((c - b) / 2000 * 1e6, (b - a) / 2000 * 1e6))
    old, new = statistics.median(p[0] for p in pairs), statistics.median(p[1] for p in pairs)
    print(f"stick step without switch: stdlib {new:.1f} us, numpy/scipy {old:.1f} us "
          f"({statistics.median(p[0] / p[1] for p in pairs):.1f}x)")
    save = []
    for _ in range(5):
        a = time.perf_counter()
        for _ in range(20000):
            plant_new.set_state(plant_new.get_state())
        b = time.perf_counter()
        for _ in range(20000):
            plant_old.set_state(plant_old.get_state())
        c = time.perf_counter()
        save.append(((b - a) / 20000 * 1e6, (c - b) / 20000 * 1e6))
    print(f"get_state + set_state: stdlib {statistics.median(s[0] for s in save):.2f} us, "
          f"before {statistics.median(s[1] for s in save):.2f} us")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 40)
