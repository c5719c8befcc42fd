"""The measurement chain as one pipeline of typed stages: recording -> marker tracks -> interval.

* :func:`track_recording`: read a recording, find (or take) the three markers in frame 0, track
  them, fill short gaps -> :class:`MarkerTracks`;
* :func:`read_tracks`: the same from a tracks CSV (``abu track``'s or anyone's);
* :func:`measure_tracks`: undistort (with a calibrated :class:`~measurement.imaging.camera.Camera`),
  analyse -> :class:`MeasureResult` (the kinematics table and the summary of ``summary.json``);
* :func:`measure_recording`: both, the whole of ``abu measure``;
* :func:`write_measurement`: ``tracks.csv``, ``kinematics.csv``, the figures and ``summary.json``.

The command line and :mod:`abu.api` call these; nothing here knows about options or argv.
SI units inside (s, rad, m); positions in pixels (x = column, y = row); frame rates in
frames/s (``fps_hz``).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable

import numpy as np

from abu_model.atomic_io import atomic_write_text
from abu_model.errors import ParameterError
from abu_model.json_text import dumps

from measurement.imaging import tracks_io
from measurement.imaging.compression import lossy_status
from measurement.inference.analysis import AnalysisOptions, analyse_tracks
from measurement.inference.lighting_models import alternative_orders
from measurement.imaging.markers import MarkerError
from measurement.imaging.track_checks import check_marker_geometry
from measurement.imaging.lost_hints import lost_hint
from measurement.kinematics.input_checks import check_motion_and_roles, check_sampling

#: The report's camera's frame rate [frames/s]: used nowhere as a default any more (a recording
#: without a stated rate needs one given, :mod:`measurement.imaging.frame_rate`); kept for
#: examples and messages.
REPORT_FPS = 4500.0
#: ``kind`` and ``format_version`` of the summary.json of ``abu measure`` (readers check them).
SUMMARY_KIND = "abu-measure-summary"
SUMMARY_VERSION = 1
#: The report's ABU: radius of the ball centre's path and ball diameter [m].
DEFAULT_L_M = 1.15e-2
DEFAULT_D_M = 3.0e-3
ROLES = ("center", "cd", "ball")


@dataclass(frozen=True)
class TrackingSettings:
    """How the markers are found and tracked (see :mod:`measurement.imaging.tracking`).

    Attributes:
        seeds_px: (3, 2) marker positions in frame 0 [px], in the order ABU centre, CD marker,
            ball; None: found automatically (:func:`measurement.imaging.markers.find_markers`).
        dark_markers: markers darker than their surroundings.
        method: centre-finding method (``isocontour``, ``report``, ``moments``).
        window_px: tracking window [px]; None (the default): sized from the markers found
            in the first frames (:mod:`measurement.imaging.window_size`; 30 px for the
            family's recordings).
        ball_reflections: 1, or 2 for the report's two-spot lighting.
        ball_method: with two reflections, ``outline`` or ``pair``.
        progress: progress bar on stderr while tracking.
        edge_step: end the ``isocontour`` method with its edge-model step
            (:mod:`measurement.imaging.edge_step`); None (the default): on the centre and CD
            markers with one reflection on the ball, never on the ball, off with two
            (:func:`measurement.imaging.edge_step_roles.edge_step_default`). ``summary.json``
            states what was used (``input.edge_step``, ``input.edge_step_markers``;
            ``tracking.json`` of ``abu track``).
    """

    seeds_px: np.ndarray | None = None
    dark_markers: bool = False
    method: str = "isocontour"
    window_px: int | None = None
    ball_reflections: int = 1
    ball_method: str = "outline"
    progress: bool = False
    edge_step: bool | None = None


@dataclass
class MarkerTracks:
    """Marker tracks of one record, lost frames filled (``lost`` says which were).

    Attributes:
        time_s: (N,) frame times [s].
        x_px, y_px: (N, 3) positions [px] of the ABU centre, CD marker and ball.
        lost: (N, 3) True where the tracker lost the marker (filled by interpolation).
        source: where the record came from (file and format).
        info: what ``tracking.json`` / ``summary.json['input']`` records (seeds, method,
            frame rate, lost frames); ``{"source": ..., "tracks_csv": True}`` for a CSV.
        frame_size_px: (width, height) of the frames [px]; None for a tracks CSV.
    """

    time_s: np.ndarray
    x_px: np.ndarray
    y_px: np.ndarray
    lost: np.ndarray
    source: str
    info: dict[str, Any]
    frame_size_px: tuple[int, int] | None = None

    def csv_text(self) -> str:
        """The ``tracks.csv`` text (time, angles, positions, lost bit mask)."""
        theta, beta = tracks_io.angles_from_pixels(self.x_px, self.y_px)
        return tracks_io.format_tracks_csv(self.time_s, theta, beta, self.x_px, self.y_px,
                                           self.lost)


def summary_field(key: str, doc: str) -> property:
    """A read-only attribute for the summary's field ``key`` (None where it is absent)."""
    return property(lambda self: self.summary.get(key), doc=doc)


@dataclass
class MeasureResult:
    """What ``abu measure`` finds for one record.

    Attributes:
        tracks: the marker tracks measured (filled, before any undistortion).
        table: time series of the analysis, column name (with unit) -> (N,) array
            (``kinematics.csv``).
        summary: the JSON-ready summary (``summary.json``; docs/measurement-analysis.md).
    """

    tracks: MarkerTracks
    table: dict[str, np.ndarray]
    summary: dict[str, Any] = field(default_factory=dict)

    mu_low = summary_field("mu_low", "lower end of the confidence interval on mu [-] "
                                      "(None: no lower bound)")
    mu_high = summary_field("mu_high", "upper end of the confidence interval on mu [-] "
                                        "(None: no upper bound)")
    status = summary_field("status", "``ok`` or why the interval is open or wide")
    confidence = summary_field("confidence", "level of the confidence sets [-]")
    mu_hat = summary_field("mu_hat", "best-fitting mu [-]")
    mu_d = summary_field("mu_d", "best-fitting sliding friction [-]")
    mu_d_low = summary_field("mu_d_low", "lower end of the interval on the sliding friction [-]")
    mu_d_high = summary_field("mu_d_high", "upper end of the interval on the sliding friction [-]")
    t_slip_s = summary_field("t_slip", "fitted slip onset [s]")
    t_slip_low_s = summary_field("t_slip_low", "last time the ball is surely stuck [s]")
    t_slip_high_s = summary_field("t_slip_high", "first time the ball surely slips [s]")
    relative_width = summary_field("relative_width", "(mu_high - mu_low) / mu_hat [-]")
    fps_hz = summary_field("fps_hz", "frame rate of the record [frames/s]")
    duration_s = summary_field("duration_s", "length of the record [s]")
    running_max = summary_field("running_max", "the report's running-max bounds (a dict)")


# ------------------------------------------------------------------------------ tracking

def _seeds(frames: np.ndarray, settings: TrackingSettings,
           log: Callable[[str], None] | None) -> tuple[np.ndarray, str]:
    """The three seeds [px] and how they were obtained."""
    from measurement.imaging.finder_stack import find_markers_stacked
    from measurement.imaging.markers import format_seeds

    if settings.seeds_px is not None:
        return np.asarray(settings.seeds_px, dtype=float), "given by --seeds"
    seeds, roles, how = find_markers_stacked(frames, dark=settings.dark_markers,
                                             ball_reflections=settings.ball_reflections)
    if log is not None:
        log(f"markers {how} (x, y px): " + ", ".join(
            f"{role} ({sx:.2f}, {sy:.2f})" for role, (sx, sy) in zip(roles, seeds)))
        log(f"  reuse or correct with --seeds '{format_seeds(seeds)}'")
    return seeds, how


def _check_seeds_inside(seeds: np.ndarray, width: int, height: int) -> None:
    from measurement.imaging.markers import format_seeds

    for i, (sx, sy) in enumerate(seeds):
        if not (0 <= sx <= width - 1 and 0 <= sy <= height - 1):
            raise ParameterError("seeds", format_seeds(seeds),
                                 f"positions inside the {width}x{height} px frame (position "
                                 f"{i + 1} is outside)")


def _warn(text: str) -> None:
    import warnings
    warnings.warn(text, UserWarning, stacklevel=4)


def _rate_info(rec, rate) -> dict[str, Any]:
    """What summary.json / tracking.json record about the frame rate and the camera file."""
    info: dict[str, Any] = {"fps_hz": rate.fps_hz, "fps_source": rate.source}
    if rate.stated_hz is not None and rate.stated_hz != rate.fps_hz:
        info["fps_stated_hz"] = rate.stated_hz
        info["fps_stated_source"] = rec.fps_source
    for key, value in (("bit_depth", rec.bit_depth),
                       ("first_frame_time_s", rec.first_frame_time_s),
                       ("video_container_fps_hz", rec.container_fps_hz)):
        if value is not None:
            info[key] = value
    return info


def track_recording(path: str | Path, *, fps_hz: float | None = None,
                    settings: TrackingSettings = TrackingSettings(),
                    check: Callable[[np.ndarray, str | None], None] | None = None,
                    log: Callable[[str], None] | None = None,
                    warn: Callable[[str], None] | None = None,
                    fps_option: str = "--fps") -> MarkerTracks:
    """Read the recording at ``path``, seed and track its three markers, fill short gaps.

    Args:
        fps_hz: frame rate [frames/s]; None: the rate the file states (camera-file header,
            our TIFF metadata; :mod:`measurement.imaging.frame_rate`). Given, it overrides the
            file's (``warn`` is told when they differ).
        check: called with the frame times [s] and where the file states its rate (None when
            given) after reading, before tracking (input checks).
        log: receives progress messages (the markers found), or None.
        warn: receives a one-line warning when ``fps_hz`` differs from the file's rate
            (None: :func:`warnings.warn`).
        fps_option: how the rate is given, for messages (``--fps``, ``fps_hz``).

    Raises:
        AbuError: unreadable recording, no frame rate known, seeds outside the frame, a marker
            lost for too long (the message names the recording and the reasons).
    """
    from measurement.imaging.frame_rate import resolve_frame_rate
    from measurement.imaging.compression import detect
    from measurement.imaging.defects import correct_defects
    from measurement.imaging.frames_io import read_recording
    from measurement.imaging.markers import format_seeds
    from measurement.imaging.reflections import track_markers
    from measurement.imaging.window_size import resolve_window

    rec = read_recording(path)
    rate = resolve_frame_rate(rec.fps_hz, rec.fps_source, fps_hz, source=rec.source,
                              option=fps_option, warn=_warn if warn is None else warn,
                              container_hz=rec.container_fps_hz)
    time = np.arange(len(rec)) / rate.fps_hz
    if check is not None:
        check(time, None if fps_hz is not None else rate.source)
    frames, defects = correct_defects(rec.frames)  # stuck pixels would capture a window
    if len(defects) and log is not None:
        log(f"replaced {len(defects)} defective (stuck) pixels by their neighbours' median")
    try:
        seeds, seeds_note = _seeds(frames, settings, log)
    except MarkerError as exc:
        raise MarkerError(f"{rec.source}, frame 0: {exc}") from None
    h, w = frames.shape[1:]
    _check_seeds_inside(seeds, w, h)
    window, window_choice = resolve_window(frames, seeds, settings.window_px, rec.source, log)
    tracks = track_markers(frames, seeds, method=settings.method, window=window,
                           dark=settings.dark_markers, progress=settings.progress,
                           ball_reflections=settings.ball_reflections,
                           ball_method=settings.ball_method, edge_step=settings.edge_step)
    lost = np.asarray(tracks.lost, dtype=bool)
    try:
        x = tracks_io.fill_lost(time, tracks.x, lost)
        y = tracks_io.fill_lost(time, tracks.y, lost)
    except tracks_io.LostMarkerError as exc:
        # Name the frame as the recording knows it (file name for a folder of frames).
        hint = lost_hint(tracks.reason, lost, seeds, tracks.window, settings.ball_reflections)
        raise tracks_io.LostMarkerError(f"{rec.source}: {exc}; lost reasons: "
                                        f"{tracks.lost_summary()}{hint}") from None
    info = {"source": rec.source, "seeds_px": format_seeds(seeds), "seeds": seeds_note,
            "roles": list(ROLES), "method": tracks.method, "window_px": tracks.window,
            "edge_step": any(tracks.stepped()),
            "edge_step_markers": [r for r, on in zip(ROLES, tracks.stepped()) if on],
            **_rate_info(rec, rate), "frames": int(time.size),
            "lost_frames": {name: int(lost[:, j].sum()) for j, name in enumerate(ROLES)},
            "lost_reasons": tracks.lost_summary(),
            "compression": detect(frames, rec.codec).summary(),
            "ball_reflections": int(settings.ball_reflections)}
    if window_choice is not None:  # as defective_pixels: only where not the family's 30 px
        info["window_choice"] = window_choice
    if len(defects):  # only then: a recording without any keeps its summary as it was
        info["defective_pixels"] = {"count": len(defects),
                                    "first_xy_px": defects[:100, ::-1].tolist()}
    return MarkerTracks(time, x, y, lost, rec.source, info, (int(w), int(h)))


def read_tracks(path: str | Path, *, fps_hz: float | None = None) -> MarkerTracks:
    """Marker tracks from a tracks CSV (lost markers filled as after tracking).

    Args:
        fps_hz: if given, must match the CSV's time column [frames/s] (a check, not a
            resampling).
    """
    table = tracks_io.read_tracks_csv(path)
    dt = float(np.median(np.diff(table.time)))
    if fps_hz is not None and abs(dt * fps_hz - 1.0) > 1e-3:
        raise ParameterError("fps", fps_hz, f"the frame rate of the tracks file "
                             f"{path} ({1.0 / dt:.6g} frames/s from its time "
                             "column), or leave --fps out")
    fps = 1.0 / dt if dt > 0 else None
    return MarkerTracks(table.time, table.x, table.y, table.lost, str(path),
                        {"source": str(path), "tracks_csv": True, "fps_hz": fps,
                         "fps_source": "time column of the tracks CSV (median interval)"})


def fill_tracks(tracks: MarkerTracks) -> MarkerTracks:
    """``tracks`` with lost positions interpolated (short gaps; long ones refused)."""
    try:
        x = tracks_io.fill_lost(tracks.time_s, tracks.x_px, tracks.lost)
        y = tracks_io.fill_lost(tracks.time_s, tracks.y_px, tracks.lost)
    except tracks_io.LostMarkerError as exc:
        raise tracks_io.LostMarkerError(f"{tracks.source}, column 'lost': {exc}") from None
    return replace(tracks, x_px=x, y_px=y)


# ------------------------------------------------------------------------------ analysis

def check_record_length(time_s: np.ndarray, source: str, options: AnalysisOptions, *,
                        fps_option: str = "--fps", rate_from: str | None = None) -> None:
    """Frame rate, record length and trim against what the estimators need.

    Args:
        source: ``fps_option`` when the user gave the rate, else the recording or tracks file.
        rate_from: where a recording states the rate it has (None: a time column or given).
    """
    check_sampling(time_s, source, fps_option=fps_option, sg_window_s=options.sg_window_s,
                   polyorder=options.sg_polyorder, estimator=options.estimator,
                   trim_s=options.trim_s, rate_from=rate_from)


def measure_tracks(tracks: MarkerTracks, *, l_m: float = DEFAULT_L_M, d_m: float = DEFAULT_D_M,
                   options: AnalysisOptions = AnalysisOptions(), camera=None,
                   camera_path: str | None = None,
                   drive: dict[str, Any] | None = None) -> MeasureResult:
    """Analyse filled marker tracks: the interval on mu and everything ``summary.json`` holds.

    Args:
        l_m, d_m: radius of the ball centre's path and ball diameter [m].
        camera: a :class:`measurement.imaging.camera.Camera` (``abu calibrate-camera``): the
            positions are undistorted and theta's harmonic prior comes from it; None: the
            family's lens prior.
        camera_path: the camera file's name, for messages and the summary.
        drive: the ``drive.json`` object of the setup (recorded for ``abu next``).
    """
    source = tracks.source
    check_marker_geometry(tracks.x_px, tracks.y_px, source)
    check_motion_and_roles(tracks.time_s, tracks.x_px, tracks.y_px, source)
    x, y, camera_info = tracks.x_px, tracks.y_px, None
    if options.line_time_s:   # a rolling shutter: each marker back to the frame times
        from measurement.imaging.rolling_shutter import positions_at_frame_times
        x, y = positions_at_frame_times(tracks.time_s, x, y, options.line_time_s)
    if options.harmonic_orders_alternative is None:   # chosen by the ball's highlights
        options = replace(options, harmonic_orders_alternative=alternative_orders(
            tracks.info.get("ball_reflections")))
    if camera is not None:
        from measurement.imaging.camera import undistort_tracks
        x, y, prior, camera_info = undistort_tracks(camera_path or "camera", camera, x, y,
                                                     tracks.frame_size_px)
        if options.inference is not None:
            options = replace(options, inference=replace(
                options.inference, theta_harmonic_rad=float(prior)))
    table, summary = analyse_tracks(tracks.time_s, x, y, l=l_m, d=d_m, lost=tracks.lost,
                                    options=options)
    info = {**tracks.info, **({"line_time_s": options.line_time_s} if options.line_time_s else {})}
    summary = {"kind": SUMMARY_KIND, "format_version": SUMMARY_VERSION, "input": info,
               **summary, **({"camera": camera_info} if camera_info else {})}
    # a lossy recording is named in the status (the bounds are not coverage-tested on it)
    summary["status"] = lossy_status(summary["status"], tracks.info.get("compression"))
    if drive is not None:
        summary["drive"] = drive
    return MeasureResult(tracks, table, summary)


def measure_recording(path: str | Path, *, fps_hz: float | None = None,
                      tracking: TrackingSettings = TrackingSettings(),
                      l_m: float = DEFAULT_L_M, d_m: float = DEFAULT_D_M,
                      options: AnalysisOptions = AnalysisOptions(), camera=None,
                      camera_path: str | None = None, drive: dict[str, Any] | None = None,
                      log: Callable[[str], None] | None = None,
                      warn: Callable[[str], None] | None = None,
                      fps_option: str = "--fps") -> MeasureResult:
    """Track and analyse a recording (the whole of ``abu measure INPUT``).

    Args:
        fps_hz: frame rate [frames/s]; None: the rate the file states (an error names
            ``fps_option`` when it states none).
        Others: as :func:`track_recording` and :func:`measure_tracks`.
    """
    def check(time_s: np.ndarray, rate_from: str | None) -> None:
        if time_s.size < tracks_io.MIN_ROWS:
            from measurement.imaging.recording_checks import RecordingError
            n = time_s.size
            raise RecordingError(f"{path}: {n} frame{'s' if n != 1 else ''}; the analysis needs "
                                 f"at least {tracks_io.MIN_ROWS}")
        check_record_length(time_s, fps_option if rate_from is None else str(path), options,
                            fps_option=fps_option, rate_from=rate_from)

    tracks = track_recording(path, fps_hz=fps_hz, settings=tracking, log=log, warn=warn,
                             fps_option=fps_option, check=check)
    return measure_tracks(tracks, l_m=l_m, d_m=d_m, options=options, camera=camera,
                          camera_path=camera_path, drive=drive)


def measure_tracks_file(path: str | Path, *, fps_hz: float | None = None,
                        l_m: float = DEFAULT_L_M, d_m: float = DEFAULT_D_M,
                        options: AnalysisOptions = AnalysisOptions(), camera=None,
                        camera_path: str | None = None,
                        drive: dict[str, Any] | None = None,
                        ball_reflections: int | None = None) -> MeasureResult:
    """Analyse a tracks CSV (the whole of ``abu measure --tracks INPUT``).

    ``ball_reflections``: how the tracked ball looked (1 or 2; None: not known, as the CSV
    does not say); it chooses the default lighting models (``AnalysisOptions``)."""
    raw = read_tracks(path, fps_hz=fps_hz)
    if ball_reflections is not None:
        if ball_reflections not in (1, 2):
            raise ParameterError("ball_reflections", ball_reflections, "1 or 2")
        raw = replace(raw, info={**raw.info, "ball_reflections": int(ball_reflections)})
    check_record_length(raw.time_s, str(path), options)
    return measure_tracks(fill_tracks(raw), l_m=l_m, d_m=d_m, options=options, camera=camera,
                          camera_path=camera_path, drive=drive)


# ------------------------------------------------------------------------------ writing

def write_measurement(result: MeasureResult, out_dir: str | Path, *,
                      plots: bool = True, figure_format: str = "png") -> list[Path]:
    """Write ``tracks.csv``, ``kinematics.csv``, the figures (``beta`` and ``kinematics``,
    ``figure_format`` png, pdf or svg) and ``summary.json`` into ``out_dir`` (an existing
    folder; each file atomically, summary.json last)."""
    from abu_model.figure_files import check_figure_format
    figure_format = check_figure_format(figure_format)
    out = Path(out_dir)
    t = result.tracks
    theta, beta = result.table["theta_rad"], result.table["beta_rad"]
    tracks_text = tracks_io.format_tracks_csv(t.time_s, theta, beta, t.x_px, t.y_px, t.lost)
    # plain CSV: units in the column names (_s, _rad, _rad_s, _rad_s2); mu_* and running_max_*
    # dimensionless; trusted 0/1; lost bit mask 1 center 2 cd 4 ball; non-finite: empty cells
    table_text = tracks_io.table_csv_text(list(result.table),
                                          [np.asarray(v) for v in result.table.values()])
    summary_text = dumps(result.summary)
    written = [out / "tracks.csv", out / "kinematics.csv"]
    atomic_write_text(written[0], tracks_text)
    atomic_write_text(written[1], table_text)
    if plots:
        from measurement.report.plots import plot_analysis  # matplotlib only when plotting
        written += plot_analysis(result.table, result.summary, out, figure_format)
    atomic_write_text(out / "summary.json", summary_text)
    return written + [out / "summary.json"]


def write_tracks(tracks: MarkerTracks, out_dir: str | Path) -> list[Path]:
    """Write ``tracks.csv`` and ``tracking.json`` (``abu track``) into ``out_dir``."""
    out = Path(out_dir)
    atomic_write_text(out / "tracks.csv", tracks.csv_text())
    atomic_write_text(out / "tracking.json", dumps(tracks.info))
    return [out / "tracks.csv", out / "tracking.json"]
