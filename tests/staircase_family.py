"""The random staircase family shared by tests/test_cosim_accuracy.py (hypothesis draws) and
tests/test_native_agreement.py (seeded draws): one builder, so both test the same family.

Family: mu in [1e-3, 6e-2]; |omega0| from 0.7 to 1.6 (also 1 - 1e-2 to 1 - 1e-6) times the speed
at which setpoint step k makes the ball slip (k = 0 when |omega| grows along the staircase), so
about a third of the cases slip at the first step; 1 to 40 steps of 1 Hz up or down in te from
0.02 to 1.5 s; t0 from 0 to 0.5 s; every rounding and both theta_ref readings; tau_motor 0, 2 or
10 ms; the end either on a setpoint step (not the first) or 0.5 s after the staircase.
"""
from __future__ import annotations

import math
import random

from abu_model.params import BallParams, PlantParams
from harness.experiments.staircase import StaircaseExperiment

HZ = 2.0 * math.pi


def family_experiment(*, mu: float, margin: float, n_steps: int, te: float, rounding: str,
                      mode: str, sign: float, end_step: int | None, t0: float,
                      tau_motor: float, k: int, up: bool) -> StaircaseExperiment:
    """The staircase of one draw (SI: te, t0, tau_motor in s; margin and k as above)."""
    plant = PlantParams(BallParams(mu=mu), tau_motor=tau_motor)
    direction = sign if up else -sign  # |omega| grows (up) or falls along the staircase
    probe = StaircaseExperiment(plant, sign * (1 + n_steps * HZ), sign, t0=t0, te=te,
                                rounding=rounding)
    # margin to the slip speed of setpoint step k (a single step from steady rotation). Where
    # |omega| falls the ball slips at or before step k (fast steps pile their responses up),
    # at a random excess of mu_req over mu and often only briefly: a slip that starts and ends
    # inside one communication step.
    k = 0 if up else min(k, len(probe.staircase.step_times) - 1)
    tk = probe.staircase.step_times[k]
    jump = 2 * 0.5 * 2.2 * HZ + (2.2**2 * tk * HZ if mode == "thesis" else 0.0)
    w0 = sign * (margin * math.sqrt(plant.ball.lever_ratio * jump / mu)
                 + (0.0 if up else (k + 1) * HZ))
    w0 = sign * max(abs(w0), (0.0 if up else n_steps * HZ) + HZ)
    steps = StaircaseExperiment(plant, w0, w0 + direction * n_steps * HZ, t0=t0, te=te,
                                rounding=rounding).staircase.step_times
    # end on a setpoint step after the first (the first would leave no stick period)
    t_end = (None if end_step is None or len(steps) < 2
             else steps[1 + end_step % (len(steps) - 1)])
    return StaircaseExperiment(plant, w0, w0 + direction * n_steps * HZ, t0=t0, te=te,
                               rounding=rounding, theta_ref_mode=mode, t_end=t_end)


def draw_experiment(rng: random.Random) -> StaircaseExperiment:
    """One seeded draw of the family (the same ranges as the hypothesis strategy)."""
    mu = rng.uniform(1e-3, 6e-2)  # the draws in this order, so the seeded cases stay the same
    margin = rng.uniform(0.7, 1.6) if rng.random() < 0.7 else 1 - 10 ** -rng.uniform(2.0, 6.0)
    n_steps, te = rng.randint(1, 40), rng.uniform(0.02, 1.5)
    rounding = rng.choice(["lead", "nearest", "trail"])
    mode = rng.choice(["integral", "thesis"])
    sign, up = rng.choice([-1.0, 1.0]), rng.random() < 0.5
    end_step, t0 = rng.choice([None, 0, 1, 2, 3]), rng.uniform(0.0, 0.5)
    tau_motor, k = rng.choice([0.0, 0.002, 0.01]), rng.randint(0, 39)
    return family_experiment(mu=mu, margin=margin, n_steps=n_steps, te=te, rounding=rounding,
                             mode=mode, sign=sign, end_step=end_step, t0=t0,
                             tau_motor=tau_motor, k=k, up=up)
