"""AbuBall alone in a co-simulation (its torque inputs fed by sources): the plant's parameters,
the probes the file can answer, and the ball's fields of an experiment's ``as_dict``. Used by
the staircase (its controller-less ramp) and the tracking drive (:mod:`.profile_run`)."""
from __future__ import annotations

from pathlib import Path
from typing import Any

from abu_model.params import PlantParams

from harness.cosim.system import Component, Source, System
from harness.experiments.fmu_files import has_output as _has_output

_PLANT_PROBES = {
    "theta": "plant.theta", "omega": "plant.omega", "alpha": "plant.alpha",
    "beta": "plant.beta", "beta_dot": "plant.beta_dot", "normal_force": "plant.normal_force",
    "friction_force": "plant.friction_force", "mu_req": "plant.mu_req", "mode": "plant.mode",
    "torque_applied": "plant.torque_applied", "mu_req_peak": "plant.mu_req_peak",
}
#: Plant outputs newer than the first interface: probed only if the AbuBall file has them
#: (without ``mu_req_peak`` the bounds fall back to mu_req at the communication points).
_OPTIONAL_PLANT_PROBES = ("mu_req_peak",)


def _plant_probes(plant_fmu: Path) -> dict[str, str]:
    """The plant's probes that the AbuBall file ``plant_fmu`` can answer."""
    return {key: ref for key, ref in _PLANT_PROBES.items()
            if key not in _OPTIONAL_PLANT_PROBES or _has_output(plant_fmu, key)}


def _plant_parameters(plant: PlantParams) -> dict[str, Any]:
    ball = plant.ball
    return {"m": ball.m, "d": ball.d, "l": ball.l, "mu": ball.mu,
            "mu_d": -1.0 if ball.mu_d is None else ball.mu_d, "J_abu": plant.J_abu,
            "tau_motor": plant.tau_motor, "ball_reaction": plant.ball_reaction}


def plant_alone(plant: PlantParams, abu_ball: Path, omega0: float, beta0: float,
                sources: tuple[Source, ...]) -> System:
    """AbuBall without the controller, its torque inputs fed by ``sources`` (the ramp and the
    tracking drive's exact loop): at rest on the rim at omega0 [rad/s], beta0 [rad]."""
    params = _plant_parameters(plant)
    params.update(theta0=0.0, omega0=omega0, beta0=beta0, beta_dot0=0.0)
    return System(components=(Component("plant", abu_ball, params),), sources=sources,
                  probes={"torque": "plant.torque", **_plant_probes(abu_ball)})


def ball_fields(plant: PlantParams) -> dict[str, Any]:
    """The ball's and the plant's parameters as an experiment's ``as_dict`` names them."""
    b = plant.ball
    return {"mu": b.mu, "mu_d": b.mu_dynamic, "m_kg": b.m, "d_m": b.d, "l_m": b.l,
            "J_abu_kg_m2": plant.J_abu, "tau_motor_s": plant.tau_motor}
