"""Recordings of the tracking drive (report ch. 6): a prescribed profile filmed by the harsh twin.

:func:`tracking_scenario` takes the camera of :func:`twin.scenario.random_scenario` (lamps,
lens, sensor, set-up geometry, all drawn from the seed) and replaces its drive by a
``tracking`` drive (:mod:`twin.drives`: the digital P law on the speed error to the profile,
bandwidth and torque lag of the ``drive.json``) and its ball by the given mu, mu_d. ``abu
render --drive tracking.json --profile profile.json --mu MU --seed N`` and
``benchmarks/bench_profile_drive.py`` render these.
"""
from __future__ import annotations

from abu_model.errors import ParameterError
from abu_model.params import BallParams
from controller.drive import Drive
from controller.profile import Profile

from twin.drives import DriveSpec, first_slip_time, rotor_mu_req
from twin.scenario import Scenario, random_scenario


def tracking_spec(drive: Drive, profile: Profile, *, bandwidth: float | None = None,
                  tau_motor: float | None = None) -> DriveSpec:
    """The twin's drive for a tracking ``drive.json`` and its profile (``bandwidth`` [rad/s]
    and ``tau_motor`` [s] override the file's: a true drive off its stated values)."""
    if not drive.is_tracking:
        raise ParameterError("--drive", drive.source, "a drive of model 'tracking' with "
                             "--profile (this one is a PI loop that follows a staircase)")
    return DriveSpec(kind="tracking", omega0=profile.omegas[0],
                     tau_motor=drive.tau_motor if tau_motor is None else tau_motor,
                     bandwidth=float(drive.bandwidth if bandwidth is None else bandwidth),
                     profile_t=tuple(profile.times), profile_w=tuple(profile.omegas))


def tracking_scenario(seed: int, spec: DriveSpec, mu: float, mu_d: float | None = None, *,
                      size: int = 256, lighting: str | None = None, n_frames: int = 3072,
                      fps: float = 4500.0) -> Scenario:
    """The seed's camera with this drive and ball (mu_d defaults to mu, the report's
    assumption)."""
    if not (0 < mu < 1):
        raise ParameterError("--mu", mu, "a static friction coefficient in (0, 1)")
    if mu_d is not None and not (0 < mu_d <= mu):
        raise ParameterError("mu_d", mu_d, f"a sliding friction coefficient in (0, mu = {mu:g}]")
    base = random_scenario(seed, size=size, lighting=lighting, n_frames=n_frames, fps=fps)
    ball = BallParams(mu=mu, mu_d=mu if mu_d is None else mu_d)
    t_pred = first_slip_time(rotor_mu_req(spec, base.times, ball)["mu_req"], base.times, mu)
    return base.with_(ball=ball, drive=spec, predicted_slip_s=t_pred)


__all__ = ["tracking_spec", "tracking_scenario"]
