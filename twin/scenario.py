"""A harsh camera twin: random scenarios drawn from one seed, simulated by the project's own
plant and filmed with physical nuisances (``abu render --scenario random --seed N``).

:func:`random_scenario` draws everything from ``numpy.random.default_rng(seed)``:

* the ball: mu in [0.005, 0.06], mu_d / mu in [0.6, 1], beta0;
* the drive (:mod:`twin.drives`): a staircase PI loop (setpoint weighting, setpoint
  filter, rounding lead / nearest / trail) or a prescribed acceleration of several bumps like
  the report's fig. 5.8, torque lag 0-30 ms; the drive is redrawn until the rotor alone predicts
  the first slip inside the recording (0.12-0.55 s, and before 80 % of a shorter record), so
  every scenario has a slip to measure;
* the light (:mod:`twin.lighting`): the report's TL ring (75 %) or two-spot indirect
  lighting with two reflections on the ball (25 %), stray side lamps (60 %), 100 Hz flicker;
* the lens and sensor (:mod:`twin.optics`): radial distortion, PSF, vignetting,
  shot / read noise, column fixed-pattern noise, saturation, motion blur;
* the set-up: pixel size 0.28-0.32 mm, the axis a few px off the frame centre, an eccentric
  centre marker (0-0.12 mm), the CD marker's radius, marker sizes and paper / ABU albedos.

:func:`render_scenario` simulates (:func:`drives.simulate_drive` on
:class:`abu_model.plant.AbuPlant`: the truth is the plant's exact state at every frame), renders
(:mod:`twin.scene`, :mod:`twin.optics`) and writes ``frames.tif``, ``truth.csv``
and ``meta.json`` (every drawn setting, unit-suffixed) atomically.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from abu_model.atomic_io import atomic_write_text
from abu_model.errors import ParameterError
from abu_model.params import BallParams

from twin.drives import DriveSpec, first_slip_time, rotor_mu_req, simulate_drive
from twin import lighting_alt
from twin.lighting import LIGHTINGS, LightingSpec, ball_sprites, make_lamps, plane_irradiance

#: Lightings ``random_scenario`` can be forced to: the first model's and the second model's
#: two-reflection lighting (:mod:`twin.lighting_alt`, never drawn unforced).
SCENARIO_LIGHTINGS = LIGHTINGS + (lighting_alt.KIND,)
from twin.optics import OpticsSpec, Sensor, distort
from twin.truth_csv import AXIS_COLUMNS, TRUTH_COLUMNS, truth_csv_text
from twin.scene import OVERSAMPLE, Sprite, _pixel_integrated, add_patch, disk_sprite, \
    subframe_positions

TWO_PI = 2.0 * math.pi
MIN_SIZE = 200
SLIP_WINDOW_S = (0.12, 0.55)


@dataclass(frozen=True)
class Scenario:
    """One harsh-twin recording (SI units; px for image quantities)."""

    seed: int
    ball: BallParams
    drive: DriveSpec
    lighting: LightingSpec | lighting_alt.AltLightingSpec
    optics: OpticsSpec
    beta0: float
    width: int = 256
    height: int = 256
    n_frames: int = 3072
    fps: float = 4500.0
    pixel_size: float = 0.3e-3
    axis_xy: tuple[float, float] = (128.3, 126.6)
    r_cd: float = 0.030
    eccentricity: float = 0.0
    eccentricity_phase: float = 0.0
    centre_radius_px: float = 6.0
    cd_radius_px: float = 4.5
    albedo_bg: float = 0.25
    albedo_marker: float = 0.85
    exposure_scale: float = 1.0
    blur_samples: int = 5
    predicted_slip_s: float | None = None

    @property
    def times(self) -> np.ndarray:
        """Frame times [s] (frame 0 at t = 0)."""
        return np.arange(self.n_frames) / self.fps

    @property
    def ball_radius_px(self) -> float:
        return 0.5 * self.ball.d / self.pixel_size

    def with_(self, **changes: Any) -> "Scenario":
        return replace(self, **changes)


# ------------------------------------------------------------------------------ drawing


def _draw_drive(rng: np.random.Generator, mu: float, times: np.ndarray, ball: BallParams
                ) -> tuple[DriveSpec, float]:
    """A drive whose rotor alone puts the first slip inside SLIP_WINDOW_S (redrawn until so)."""
    u = rng.uniform
    lo, hi = SLIP_WINDOW_S
    hi = min(hi, 0.8 * float(times[-1]))  # short records: the slip stays clear of the end
    # the categories are drawn once (only the continuous settings are redrawn), so the slip
    # placement does not bias the mix of drive kinds and roundings
    kind = "staircase_pi" if rng.random() < 0.6 else "profile"
    rounding = str(rng.choice(["lead", "nearest", "trail"]))
    for attempt in range(1000):
        if attempt == 500:  # this combination cannot place the slip: draw the categories again
            kind = "staircase_pi" if kind == "profile" else "profile"
        tau = u(0.0, 0.03)
        # lower speeds for larger mu keep the needed acceleration within a drive's reach
        w0 = -TWO_PI * u(5.0, 14.0) * math.sqrt(0.03 / max(mu, 0.012)) ** 0.5
        if kind == "staircase_pi":
            spec = DriveSpec(
                kind="staircase_pi", omega0=w0, tau_motor=tau,
                omega_end=w0 - TWO_PI * u(6.0, 14.0), t0=u(0.0, 0.05), te=u(0.3, 0.7),
                rounding=rounding, zeta=u(0.6, 1.0),
                omega_n=u(8.0, 30.0), setpoint_weight=u(0.5, 1.0),
                setpoint_tau=0.0 if rng.random() < 0.4 else u(0.002, 0.02))
        else:
            n_b = int(rng.integers(3, 9))
            spacing = u(0.018, 0.045)
            start = u(0.06, 0.2)
            amps = [(0.5 + 0.5 * k / (n_b - 1)) * u(0.8, 1.2) for k in range(n_b)]
            bumps = tuple((start + k * spacing, spacing * u(0.4, 0.7), a)
                          for k, a in enumerate(amps))
            peak_target = mu * u(1.05, 1.6)
            scale = 0.95 * mu * w0 * w0 / ball.lever_ratio  # a first guess [rad/s^2]
            spec = None
            for _ in range(4):  # fixed-point on the amplitude: peak mu_req -> peak_target
                spec = DriveSpec(kind="profile", omega0=w0, tau_motor=tau,
                                 bumps=tuple((t, w, a * scale) for t, w, a in bumps),
                                 base_accel=scale * u(0.1, 0.5), base_t0=u(0.0, 0.05),
                                 base_rise=u(0.05, 0.2))
                peak = float(rotor_mu_req(spec, times, ball)["mu_req"].max())
                scale *= peak_target / peak
        rot = rotor_mu_req(spec, times, ball)
        t_slip = first_slip_time(rot["mu_req"], times, mu)
        if t_slip is not None and lo <= t_slip <= hi:
            return spec, t_slip
    raise ParameterError("seed", "drive search", "a drive slipping inside the recording")


def random_scenario(seed: int, *, size: int = 256, lighting: str | None = None,
                    n_frames: int = 3072, fps: float = 4500.0) -> Scenario:
    """Draw one scenario of the harsh family from ``seed`` (see the module doc).

    Args:
        seed: the only source of randomness (same seed, same scenario, same frames).
        size: frame width = height [px] (>= 200; below 256 the CD marker moves inwards).
        lighting: force ``ring`` or ``two_spot`` (default: drawn, 25 % two_spot).
        n_frames, fps: recording length [-] and frame rate [frames/s].
    """
    if isinstance(size, bool) or not isinstance(size, (int, np.integer)) or size < MIN_SIZE:
        raise ParameterError("size", size, f"an integer >= {MIN_SIZE} px")
    if lighting is not None and lighting not in SCENARIO_LIGHTINGS:
        raise ParameterError("lighting", lighting, f"one of {', '.join(SCENARIO_LIGHTINGS)}")
    if isinstance(n_frames, bool) or not isinstance(n_frames, (int, np.integer)) \
            or n_frames < 1000:
        raise ParameterError("frames", n_frames, "an integer >= 1000 (the slip is placed at "
                             f"{SLIP_WINDOW_S[0]}-{SLIP_WINDOW_S[1]} s)")
    rng = np.random.default_rng(seed)
    u = rng.uniform
    mu = u(0.005, 0.06)
    ball = BallParams(mu=mu, mu_d=mu * u(0.6, 1.0))
    times = np.arange(n_frames) / fps
    drive, t_pred = _draw_drive(rng, mu, times, ball)
    kind = lighting or ("two_spot" if rng.random() < 0.25 else "ring")
    light = make_lamps("two_spot" if kind == lighting_alt.KIND else kind, rng,
                       stray=rng.random() < 0.6)
    if kind == lighting_alt.KIND:   # the second model, drawn after the first (same stream)
        light = lighting_alt.make_alt_lighting(rng)
    c = (size - 1) / 2.0
    ps = u(0.28e-3, 0.32e-3)
    # the CD marker >= 30 px outside the ball's path, so their tracking windows never overlap
    r_cd_px = min(0.030 / ps * u(0.92, 1.0), size / 2.0 - 24.0)
    optics = OpticsSpec(k1=u(-0.03, 0.03), k2=u(-0.01, 0.01),
                        optical_centre=(c + u(-5, 5), c + u(-5, 5)), psf_sigma=u(0.4, 0.9),
                        vignetting=u(0.0, 0.5), conversion_gain=u(2.0, 10.0),
                        read_noise=u(1.0, 3.0), column_offset_sigma=u(0.0, 2.0),
                        column_gain_sigma=u(0.0, 0.02), exposure_fraction=u(0.1, 0.5))
    return Scenario(
        seed=int(seed), ball=ball, drive=drive, lighting=light, optics=optics,
        beta0=u(1.2, TWO_PI - 2.6), width=int(size), height=int(size), n_frames=int(n_frames),
        fps=float(fps), pixel_size=ps, axis_xy=(c + u(-3, 3), c + u(-3, 3)),
        r_cd=r_cd_px * ps, eccentricity=u(0.0, 0.12e-3), eccentricity_phase=u(0, TWO_PI),
        centre_radius_px=u(5.0, 7.0), cd_radius_px=u(4.0, 5.5), albedo_bg=u(0.15, 0.35),
        albedo_marker=u(0.75, 0.95), exposure_scale=u(35.0, 70.0), predicted_slip_s=t_pred)


def magnified(scn: Scenario, zoom: float) -> Scenario:
    """``scn`` seen by a camera ``zoom`` times closer: pixel size / zoom about the frame's
    centre (axis, optical centre and the paper markers' image radii scale; the ball's follows
    from its size over the pixel size). For recordings outside the family's magnification."""
    if not zoom > 0:
        raise ParameterError("zoom", zoom, "a magnification factor > 0")
    c = (scn.width - 1) / 2.0
    ax, ay = scn.axis_xy
    oc = scn.optics.optical_centre
    return scn.with_(pixel_size=scn.pixel_size / zoom,
                     axis_xy=(c + (ax - c) * zoom, c + (ay - c) * zoom),
                     centre_radius_px=scn.centre_radius_px * zoom,
                     cd_radius_px=scn.cd_radius_px * zoom,
                     optics=replace(scn.optics, optical_centre=(c + (oc[0] - c) * zoom,
                                                                c + (oc[1] - c) * zoom)))


# ------------------------------------------------------------------------------ simulation


def marker_positions(scn: Scenario, theta: np.ndarray, beta: np.ndarray
                     ) -> dict[str, np.ndarray]:
    """Image positions (N, 2) [px], after lens distortion, of the axis, the (eccentric) centre
    marker, the CD marker and the ball's geometric centre."""
    ps = scn.pixel_size
    ax, ay = scn.axis_xy

    def px(r: np.ndarray | float, a: np.ndarray) -> np.ndarray:
        return np.stack([ax + r / ps * np.cos(a), ay - r / ps * np.sin(a)], axis=-1)

    n = theta.shape[0]
    ideal = {"axis": np.tile([ax, ay], (n, 1)),
             "centre": px(scn.eccentricity, theta + scn.eccentricity_phase),
             "cd": px(scn.r_cd, theta), "ball": px(scn.ball.l, theta + beta)}
    return {k: distort(v, scn.optics, scn.width, scn.height) for k, v in ideal.items()}


def rolling_shutter_positions(scn: Scenario, state: dict[str, np.ndarray],
                              pos: dict[str, np.ndarray], readout: float
                              ) -> dict[str, np.ndarray]:
    """``pos`` as a rolling shutter sees it: rows read top first over ``readout`` frame
    intervals, each marker where the plant had it when its row was read (frame time + row /
    height x readout / fps; the state's theta, beta between frames by cubic splines)."""
    from scipy.interpolate import CubicSpline

    t = scn.times
    theta, beta = CubicSpline(t, state["theta"]), CubicSpline(t, state["beta"])
    out = dict(pos)
    for k in ("centre", "cd", "ball"):
        taken = t + readout / scn.fps * pos[k][:, 1] / scn.height
        out[k] = marker_positions(scn, theta(taken), beta(taken))[k]
    return out


def simulate_scenario(scn: Scenario) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """(true state per frame, marker image positions per frame)."""
    state = simulate_drive(scn.drive, scn.ball, scn.times, beta0=scn.beta0)
    return state, marker_positions(scn, state["theta"], state["beta"])


def with_lead(scn: Scenario, state: dict[str, np.ndarray], lead_s: float
              ) -> tuple[Scenario, dict[str, np.ndarray], dict[str, np.ndarray]]:
    """(scenario, state, marker positions) with the drive's constant starting speed held
    ``lead_s`` [s] longer before the scenario: the ball stuck that long, a late slip in a long
    record. The state's arrays and switch times are shifted by the lead.

    Raises:
        ParameterError: a drive that starts accelerating (a smooth profile) cannot be
            extended back; or a negative lead.
    """
    if not lead_s >= 0.0:
        raise ParameterError("lead", lead_s, "a time >= 0 s")
    # held at a constant speed (omega_dot = 0, so mu_req = 0) the ball sticks
    if state["alpha"][0] != 0.0:
        raise ParameterError("lead", lead_s, f"a drive that starts at a constant speed "
                             f"(seed {scn.seed} starts accelerating)")
    lead = int(round(lead_s * scn.fps))
    n = scn.n_frames
    out = {k: np.r_[np.full(lead, v[0]), v] if np.ndim(v) and len(v) == n else v
           for k, v in state.items()}
    out["theta"][:lead] += state["omega"][0] * (np.arange(-lead, 0) / scn.fps)
    out["switches"] = np.asarray(state["switches"], float) + lead / scn.fps
    scn = scn.with_(n_frames=n + lead)
    return scn, out, marker_positions(scn, out["theta"], out["beta"])


# ------------------------------------------------------------------------------ rendering


def render_scenario_frames(scn: Scenario, state: dict[str, np.ndarray],
                           pos: dict[str, np.ndarray], *, chunk: int = 256) -> np.ndarray:
    """(N, H, W) uint8 frames of the scenario."""
    rng = np.random.default_rng([scn.seed, 1])
    w, h = scn.width, scn.height
    yy, xx = np.mgrid[0:h, 0:w].astype(float)
    ax, ay = scn.axis_xy
    alt = isinstance(scn.lighting, lighting_alt.AltLightingSpec)
    plane_e, sprites_of = (lighting_alt.plane_irradiance, lighting_alt.ball_sprites) if alt \
        else (plane_irradiance, ball_sprites)
    E = plane_e(scn.lighting, (xx - ax) * scn.pixel_size, -(yy - ay) * scn.pixel_size)
    s = scn.exposure_scale / (float(plane_e(scn.lighting, np.zeros(1), np.zeros(1))[0])
                              * scn.albedo_bg)
    bg = (s * scn.albedo_bg * E).astype(np.float32)
    mk = (s * (scn.albedo_marker - scn.albedo_bg) * E).astype(np.float32)
    n_phi = 96
    sprites, _, half = sprites_of(scn.lighting, scn.ball.l, scn.ball_radius_px,
                                  0.5 * scn.ball.d, n_phi=n_phi, oversample=OVERSAMPLE)
    if alt:   # the second model's radiance is relative to the plane's
        sprites = sprites * np.float32(scn.albedo_bg)
    ball_spr = Sprite(_pixel_integrated(sprites * np.float32(s), OVERSAMPLE), half)
    ball_cov = Sprite(*disk_sprite(scn.ball_radius_px))
    ball_cov.B = ball_cov.B[None]
    disks = []
    for name, r in (("centre", scn.centre_radius_px), ("cd", scn.cd_radius_px)):
        spr = Sprite(*disk_sprite(r))
        spr.B = spr.B[None]
        disks.append((name, spr))
    o = scn.optics
    sub = {}
    for k in ("centre", "cd", "ball"):
        # sub-frame samples where the marker moves: one per 0.2 px of travel in the exposure
        # (up to blur_samples; the centre marker barely moves and needs one)
        travel = o.exposure_fraction * float(np.max(np.hypot(*np.diff(pos[k], axis=0).T),
                                                    initial=0.0))
        n_sub = int(np.clip(1 + math.ceil(travel / 0.2), 1, scn.blur_samples))
        sub[k] = subframe_positions(pos[k], o.exposure_fraction, n_sub)
    phi = np.mod(state["theta"] + state["beta"], TWO_PI)
    kphi = np.rint(phi / TWO_PI * n_phi).astype(np.int64) % n_phi
    sensor = Sensor(o, w, h, scn.lighting.flicker, scn.lighting.flicker_phase, rng)
    times = scn.times
    out = np.empty((scn.n_frames, h, w), dtype=np.uint8)
    for a in range(0, scn.n_frames, chunk):
        b = min(scn.n_frames, a + chunk)
        img = np.broadcast_to(bg, (b - a, h, w)).copy()
        for name, spr in disks:
            vals, x0, y0 = spr.patch(sub[name][a:b], None, w, h)
            add_patch(img, vals, x0, y0, mk)
        vals, x0, y0 = ball_cov.patch(sub["ball"][a:b], None, w, h)
        add_patch(img, -vals, x0, y0, bg)
        vals, x0, y0 = ball_spr.patch(sub["ball"][a:b], kphi[a:b], w, h)
        add_patch(img, vals, x0, y0)
        out[a:b] = sensor.apply(img, times[a:b])
    return out


# ------------------------------------------------------------------------------ files


def _truth_csv(scn: Scenario, st: dict[str, np.ndarray], pos: dict[str, np.ndarray]) -> str:
    values = {"time_s": scn.times, "x_center_px": pos["centre"][:, 0],
              "y_center_px": pos["centre"][:, 1], "x_cd_px": pos["cd"][:, 0],
              "y_cd_px": pos["cd"][:, 1], "x_ball_px": pos["ball"][:, 0],
              "y_ball_px": pos["ball"][:, 1],
              # the random family's ball has no separate apparent centre in its truth
              "x_ball_apparent_px": pos["ball"][:, 0], "y_ball_apparent_px": pos["ball"][:, 1],
              "theta_rad": st["theta"], "beta_rad": st["beta"], "omega_rad_s": st["omega"],
              "omega_dot_rad_s2": st["alpha"], "beta_dot_rad_s": st["beta_dot"],
              "omega_ref_rad_s": st["omega_ref"], "mu_req": st["mu_req"], "mode": st["mode"],
              "x_axis_px": pos["axis"][:, 0], "y_axis_px": pos["axis"][:, 1]}
    return truth_csv_text(TRUTH_COLUMNS + AXIS_COLUMNS, values)


def scenario_meta(scn: Scenario, st: dict[str, np.ndarray], pos: dict[str, np.ndarray]) -> dict:
    """meta.json content: every drawn setting (unit-suffixed keys) and the simulated slip."""
    from measurement.imaging.markers import format_seeds

    mode = st["mode"]
    slipping = np.flatnonzero(mode != 0)
    sw = st["switches"]
    first = sw[0] if sw.size else None
    stuck = (np.arange(scn.n_frames) < (slipping[0] if slipping.size else scn.n_frames))
    from twin.report_twin import RENDER_META_KIND, RENDER_META_VERSION
    return {
        "kind": RENDER_META_KIND, "format_version": RENDER_META_VERSION,
        "description": "harsh camera twin (twin.scenario): drive simulated on "
                       "abu_model.plant.AbuPlant, physically lit and filmed",
        "files": {"frames": "frames.tif", "truth": "truth.csv"},
        "scenario": "random", "seed": scn.seed,
        "fps": scn.fps, "frame_interval_s": 1.0 / scn.fps, "n_frames": scn.n_frames,
        "time_first_frame_s": 0.0, "frame_size_px": [scn.width, scn.height],
        "seeds": format_seeds(np.stack([pos["centre"][0], pos["cd"][0], pos["ball"][0]])),
        "seeds_roles": ["centre", "cd", "ball"],
        "ball_reflections": scn.lighting.reflections,
        "mu": scn.ball.mu, "mu_d": scn.ball.mu_dynamic,
        "mu_d_over_mu": scn.ball.mu_dynamic / scn.ball.mu,
        "geometry": {"l_m": scn.ball.l, "d_m": scn.ball.d, "m_kg": scn.ball.m,
                     "r_cd_m": scn.r_cd, "pixel_size_m_per_px": scn.pixel_size,
                     "axis_x_px": scn.axis_xy[0], "axis_y_px": scn.axis_xy[1],
                     "l_px": scn.ball.l / scn.pixel_size, "r_cd_px": scn.r_cd / scn.pixel_size,
                     "ball_radius_px": scn.ball_radius_px,
                     "centre_marker_eccentricity_m": scn.eccentricity,
                     "centre_marker_eccentricity_phase_rad": scn.eccentricity_phase,
                     "centre_marker_radius_px": scn.centre_radius_px,
                     "cd_marker_radius_px": scn.cd_radius_px,
                     "albedo_background": scn.albedo_bg, "albedo_markers": scn.albedo_marker,
                     "convention": "x = column, y = row (down); theta = atan2(-(y_cd - y_c), "
                                   "x_cd - x_c); beta = angle(centre->ball) - theta"},
        "simulation": {
            "t_slip_s": first, "switch_times_s": sw.tolist(),
            "predicted_slip_s": scn.predicted_slip_s,
            "first_slip_frame": int(slipping[0]) if slipping.size else None,
            "mu_req_max_stuck": float(np.max(st["mu_req"][stuck])) if stuck.any() else None,
            "omega_dot_peak_rad_s2": float(np.max(np.abs(st["alpha"]))),
            "mode_first_frame": int(mode[0]),
        },
        "drive": scn.drive.to_dict(),
        "lighting": scn.lighting.to_dict(),
        "optics": {**scn.optics.to_dict(), "blur_samples": scn.blur_samples,
                   "exposure_scale_grey": scn.exposure_scale},
        "units": {"fps": "frames/s", "mu": "1", "mu_d": "1", "seeds": "px"},
    }


def render_scenario(out_dir: str | Path, scn: Scenario) -> Path:
    """Simulate and film ``scn``; write frames.tif, truth.csv, meta.json atomically."""
    from measurement.report.json_text import dumps
    from measurement.imaging.frames_io import write_multipage_tiff

    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise ParameterError("--out", str(out), "a folder (it exists and is a file)")
    state, pos = simulate_scenario(scn)
    frames = render_scenario_frames(scn, state, pos)
    meta = scenario_meta(scn, state, pos)
    truth = _truth_csv(scn, state, pos)
    out.mkdir(parents=True, exist_ok=True)
    write_multipage_tiff(out / "frames.tif", frames, fps_hz=scn.fps, first_frame_time_s=0.0)
    atomic_write_text(out / "truth.csv", truth)
    atomic_write_text(out / "meta.json", dumps(meta))
    return out


__all__ = ["Scenario", "random_scenario", "simulate_scenario", "render_scenario",
           "render_scenario_frames", "TRUTH_COLUMNS"]
