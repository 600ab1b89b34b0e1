"""The rerun recording of one run: the map, the truth, the sonar scans and the sensor series.

Everything time-varying is sent in bulk with ``send_columns`` on one ``time`` timeline
(seconds since the start of the run): one call per entity, never one log call per sample.
Entity paths (the tests read them back):

- ``world/map/walls``: the map segments, static ``LineStrips2D``;
- ``world/robot/path``: the whole true trajectory, static ``LineStrips2D``;
- ``world/robot/footprint``: the true position with the footprint disk, ``Ellipses2D`` (N rows);
- ``world/robot/heading``: an arrow along the true heading, ``Arrows2D`` (N rows);
- ``world/sonar/cones``: each sensor's cone at each scan, out to the reading (or to ``d_max``
  when there is no echo), ``LineStrips2D`` (M rows of k strips);
- ``world/sonar/echoes``: the point of each finite reading on its sensor's axis, ``Points2D``
  (M rows);
- ``sensors/encoders/left``, ``sensors/encoders/right``: ticks per sample, ``Scalars`` (N);
- ``sensors/gyro/rate_rad_s``: ``Scalars`` (N);
- ``sensors/accelerometer/x_m_s2``, ``.../y_m_s2``: body-frame specific force, ``Scalars`` (N);
- ``truth/v_m_s``, ``truth/omega_rad_s``: true body velocity, ``Scalars`` (N).

The localisation pipeline (when the run has an estimation):

- ``world/intervals/boxes``: the (x, y) projections of the outer boxes of each epoch,
  ``Boxes2D`` (E rows of K boxes; inner boxes drawn in another colour);
- ``world/intervals/hull``: the hull of each epoch's outer set, ``Boxes2D`` (E rows; an
  inconsistent or lost epoch has none);
- ``world/estimates/ukf_only/path``, ``world/estimates/fused/path``: static trajectories;
- ``world/estimates/<branch>/position``: ``Points2D`` at every ``ESTIMATE_STRIDE``-th sample;
- ``world/estimates/<branch>/ellipse``: the ``ELLIPSE_SIGMA``-sigma position covariance
  ellipse, ``LineStrips2D`` at the same samples;
- ``intervals/box_width_m``, ``intervals/area_m2``, ``intervals/q_used``,
  ``intervals/epoch_ms``, ``intervals/status`` (the index of ``scenarios.epochs.STATUS``:
  0 global, 1 tracking, 2 inconsistent, 3 lost): per-epoch figures, ``Scalars`` (E);
- ``errors/position_m/<branch>``, ``errors/heading_rad/<branch>``: estimation errors,
  ``Scalars`` at the same samples as the estimates.

The default blueprint puts the 2-D map view (map, truth, boxes and both estimates) beside
the time series.
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from robotsim.robot import wrap_angle
from scenarios.errors import InternalError
from scenarios.outputs import write_bytes
from scenarios.runner import BRANCHES

if TYPE_CHECKING:
    from robotsim.sensors.sonar import SonarBeltParams
    from robotsim.simulation import SimulationLog
    from scenarios.epochs import EpochLog
    from scenarios.runner import Estimation
    from scenarios.spec import ScenarioSpec

APPLICATION_ID = "robotsim"
TIMELINE = "time"

#: Points on the arc of each drawn sonar cone.
CONE_ARC_POINTS = 7

WALL_COLOR = (200, 200, 200)
TRUTH_COLOR = (60, 200, 80)
CONE_ECHO_COLOR = (90, 160, 255)
CONE_NO_ECHO_COLOR = (90, 90, 90)
ECHO_COLOR = (255, 140, 0)
BOX_COLOR = (230, 60, 60)
INNER_BOX_COLOR = (255, 170, 170)
HULL_COLOR = (150, 30, 30)
BRANCH_COLORS = {"ukf_only": (80, 120, 255), "fused": (255, 200, 0)}

#: The estimates are drawn at every this many samples (10 Hz at the default 100 Hz).
ESTIMATE_STRIDE = 10
#: Points on each covariance ellipse, and its size in standard deviations.
ELLIPSE_POINTS = 25
ELLIPSE_SIGMA = 2.0


def write_recording(
    path: str | Path, spec: ScenarioSpec, log: SimulationLog, estimation: Estimation | None = None
) -> None:
    """Write the recording of ``log`` (a run of ``spec``) and of its ``estimation`` (if any)
    to the ``.rrd`` file ``path``, then read it back (:func:`verify_recording`).

    rerun encodes into memory (a binary stream) and this function writes the bytes: rerun's
    own file sink only logs a failed write (a full disk) and then blocks on disconnect, so a
    truncated file could not be told from a complete one. Here a failed write raises an
    ``OSError`` naming ``path``.
    """
    recording_id = f"{spec.name}-seed{spec.run.seed}"
    rec = rr.RecordingStream(APPLICATION_ID, recording_id=recording_id)
    stream = rr.binary_stream(rec)
    rec.send_blueprint(default_blueprint(), make_active=False, make_default=True)
    record_run(rec, spec, log)
    if estimation is not None:
        record_estimation(rec, log, estimation)
    rec.flush()
    rec.disconnect()
    data = stream.read()
    write_bytes(path, b"" if data is None else data)
    verify_recording(path, recording_id)


def verify_recording(path: str | Path, recording_id: str) -> None:
    """Read the ``.rrd`` file ``path`` back with rerun's reader: it must end with its footer
    (the manifest rerun writes last) and hold the recording ``recording_id``.

    Raises:
        InternalError: the file is truncated, unreadable or holds another recording.
    """
    from rerun.chunk import RrdReader

    try:
        with warnings.catch_warnings():  # a file without footer also warns: the error says it
            warnings.simplefilter("ignore")
            reader = RrdReader(path)
            found = [entry.recording_id for entry in reader.recordings()]
            reader.store()  # reads the footer's manifest: fails on a truncated file
    except (RuntimeError, ValueError, OSError) as exc:
        raise InternalError(f"the recording {path} does not read back: {exc}") from exc
    if found != [recording_id]:
        raise InternalError(f"the recording {path} holds {found}, not [{recording_id!r}]")


def default_blueprint() -> rrb.Blueprint:
    """The 2-D map view (world) beside the sensor and truth time series."""
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial2DView(origin="world", name="map"),
            rrb.Vertical(
                rrb.TimeSeriesView(origin="sensors/encoders", name="encoders (ticks per sample)"),
                rrb.TimeSeriesView(origin="sensors/gyro", name="gyro (rad/s)"),
                rrb.TimeSeriesView(origin="sensors/accelerometer", name="accelerometer (m/s²)"),
                rrb.TimeSeriesView(origin="truth", name="true velocity"),
                rrb.TimeSeriesView(origin="intervals", name="interval epochs (box size, q, time)"),
                rrb.TimeSeriesView(origin="errors", name="estimation errors"),
            ),
            column_shares=[3, 2],
        ),
        collapse_panels=True,
    )


def record_run(rec: rr.RecordingStream, spec: ScenarioSpec, log: SimulationLog) -> None:
    """Send the map, the truth, the sonar scans and the sensor series of one run to ``rec``."""
    record_map(rec, spec.map.segments)
    record_truth(rec, log.t_s, log.pose, log.velocity, spec.robot.radius_m)
    record_sonar(rec, log.sonar_t_s, log.sonar_pose, log.sonar_range_m, spec.sensors.sonar)
    record_proprioceptive(rec, log.t_s, log.wheel_ticks, log.gyro_rad_s, log.accel_m_s2)


def record_map(rec: rr.RecordingStream, segments: np.ndarray) -> None:
    """The map walls ``(m, 2, 2)``, static."""
    rec.log(
        "world/map/walls", rr.LineStrips2D(segments, colors=WALL_COLOR, radii=0.03), static=True
    )


def record_truth(
    rec: rr.RecordingStream,
    t_s: np.ndarray,
    pose: np.ndarray,
    velocity: np.ndarray,
    radius_m: float,
) -> None:
    """The true path (static), footprint and heading ``pose (N, 3)``, and velocity ``(N, 2)``."""
    times = [rr.TimeColumn(TIMELINE, duration=t_s)]
    xy = np.ascontiguousarray(pose[:, :2])
    n = len(t_s)
    rec.log("world/robot/path", rr.LineStrips2D([xy], colors=TRUTH_COLOR, radii=0.01), static=True)
    rec.send_columns(
        "world/robot/footprint",
        indexes=times,
        columns=rr.Ellipses2D.columns(centers=xy, half_sizes=np.full((n, 2), radius_m)),
    )
    heading = radius_m * np.stack([np.cos(pose[:, 2]), np.sin(pose[:, 2])], axis=1)
    rec.send_columns(
        "world/robot/heading",
        indexes=times,
        columns=rr.Arrows2D.columns(origins=xy, vectors=heading),
    )
    rec.send_columns(
        "truth/v_m_s", indexes=times, columns=rr.Scalars.columns(scalars=velocity[:, 0])
    )
    rec.send_columns(
        "truth/omega_rad_s", indexes=times, columns=rr.Scalars.columns(scalars=velocity[:, 1])
    )


def sensor_positions(
    sonar_pose: np.ndarray, mount_xy_m: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """World positions ``x, y`` ``(M, k)`` of the sensors: ``s_i = (x, y) + R(theta) s~_i``."""
    x, y, theta = sonar_pose[:, 0, None], sonar_pose[:, 1, None], sonar_pose[:, 2, None]
    cos_t, sin_t = np.cos(theta), np.sin(theta)
    return (
        x + cos_t * mount_xy_m[:, 0] - sin_t * mount_xy_m[:, 1],
        y + sin_t * mount_xy_m[:, 0] + cos_t * mount_xy_m[:, 1],
    )


def cone_outlines(
    sonar_pose: np.ndarray,
    range_m: np.ndarray,
    mount_xy_m: np.ndarray,
    mount_angle_rad: np.ndarray,
    half_aperture_rad: float,
    d_max_m: float,
) -> np.ndarray:
    """Closed outlines ``(M, k, CONE_ARC_POINTS + 2, 2)`` of every cone at every scan.

    Each outline goes from the sensor, out along one edge to the reading (``d_max_m`` when
    there is no echo), round the arc, and back to the sensor.
    """
    sx, sy = sensor_positions(sonar_pose, mount_xy_m)
    theta = sonar_pose[:, 2, None]
    reach = np.where(np.isfinite(range_m), range_m, d_max_m)  # (M, k)
    arc = np.linspace(-half_aperture_rad, half_aperture_rad, CONE_ARC_POINTS)
    phi = (theta + mount_angle_rad)[..., None] + arc  # (M, k, A)
    arc_x = sx[..., None] + reach[..., None] * np.cos(phi)
    arc_y = sy[..., None] + reach[..., None] * np.sin(phi)
    outline = np.empty((*range_m.shape, CONE_ARC_POINTS + 2, 2))
    outline[..., 0, 0], outline[..., 0, 1] = sx, sy
    outline[..., 1:-1, 0], outline[..., 1:-1, 1] = arc_x, arc_y
    outline[..., -1, :] = outline[..., 0, :]
    return outline


def echo_points(
    sonar_pose: np.ndarray, range_m: np.ndarray, mount_xy_m: np.ndarray, mount_angle_rad: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """World points ``(E, 2)`` of the finite readings on their sensors' axes, and counts ``(M,)``."""
    sx, sy = sensor_positions(sonar_pose, mount_xy_m)
    theta = sonar_pose[:, 2, None]
    echo = np.isfinite(range_m)
    reach = np.where(echo, range_m, 0.0)
    phi = theta + mount_angle_rad
    points = np.stack([sx + reach * np.cos(phi), sy + reach * np.sin(phi)], axis=-1)
    return points[echo], echo.sum(axis=1)


def record_sonar(
    rec: rr.RecordingStream,
    sonar_t_s: np.ndarray,
    sonar_pose: np.ndarray,
    range_m: np.ndarray,
    belt: SonarBeltParams,
) -> None:
    """The cones ``(M scans x k sensors)`` and the echo points of every scan of ``belt``."""
    scans, sensors = range_m.shape
    if scans == 0:
        return
    times = [rr.TimeColumn(TIMELINE, duration=sonar_t_s)]
    outlines = cone_outlines(
        sonar_pose,
        range_m,
        belt.mount_xy,
        belt.mount_angle_rad,
        belt.half_aperture_rad,
        belt.d_max_m,
    )
    colors = np.where(np.isfinite(range_m)[..., None], CONE_ECHO_COLOR, CONE_NO_ECHO_COLOR).astype(
        np.uint8
    )
    rec.send_columns(
        "world/sonar/cones",
        indexes=times,
        columns=rr.LineStrips2D.columns(
            strips=outlines.reshape(scans * sensors, -1, 2), colors=colors.reshape(-1, 3)
        ).partition(np.full(scans, sensors)),
    )
    points, counts = echo_points(sonar_pose, range_m, belt.mount_xy, belt.mount_angle_rad)
    rec.send_columns(
        "world/sonar/echoes",
        indexes=times,
        columns=rr.Points2D.columns(
            positions=points, colors=np.tile(ECHO_COLOR, (len(points), 1))
        ).partition(counts),
    )


def record_proprioceptive(
    rec: rr.RecordingStream,
    t_s: np.ndarray,
    wheel_ticks: np.ndarray,
    gyro_rad_s: np.ndarray,
    accel_m_s2: np.ndarray,
) -> None:
    """Encoder ticks ``(N, 2)``, gyro rate ``(N,)`` and specific force ``(N, 2)`` series."""
    times = [rr.TimeColumn(TIMELINE, duration=t_s)]
    series = {
        "sensors/encoders/left": wheel_ticks[:, 0],
        "sensors/encoders/right": wheel_ticks[:, 1],
        "sensors/gyro/rate_rad_s": gyro_rad_s,
        "sensors/accelerometer/x_m_s2": accel_m_s2[:, 0],
        "sensors/accelerometer/y_m_s2": accel_m_s2[:, 1],
    }
    for entity, values in series.items():
        rec.send_columns(
            entity,
            indexes=times,
            columns=rr.Scalars.columns(scalars=np.asarray(values, dtype=np.float64)),
        )


def record_estimation(rec: rr.RecordingStream, log: SimulationLog, estimation: Estimation) -> None:
    """The interval sets, both branches' estimates with their ellipses, and the per-epoch
    figures of one run."""
    record_interval_sets(rec, estimation.epochs)
    every = slice(None, None, ESTIMATE_STRIDE)
    times = [rr.TimeColumn(TIMELINE, duration=log.t_s[every])]
    truth = log.pose[every]
    for b, branch in enumerate(BRANCHES):
        pose, cov = estimation.pose[b], estimation.pose_cov[b]
        color = BRANCH_COLORS[branch]
        base = f"world/estimates/{branch}"
        rec.log(
            f"{base}/path",
            rr.LineStrips2D([np.ascontiguousarray(pose[:, :2])], colors=color, radii=0.01),
            static=True,
        )
        shown = pose[every]
        rec.send_columns(
            f"{base}/position", indexes=times, columns=rr.Points2D.columns(positions=shown[:, :2])
        )
        rec.log(f"{base}/position", rr.Points2D.from_fields(colors=color, radii=0.05), static=True)
        outlines = covariance_ellipses(shown[:, :2], cov[every, :2, :2])
        rec.send_columns(
            f"{base}/ellipse", indexes=times, columns=rr.LineStrips2D.columns(strips=outlines)
        )
        rec.log(
            f"{base}/ellipse", rr.LineStrips2D.from_fields(colors=color, radii=0.01), static=True
        )
        error_xy = np.linalg.norm(shown[:, :2] - truth[:, :2], axis=1)
        error_theta = np.abs(wrap_angle(shown[:, 2] - truth[:, 2]))
        rec.send_columns(
            f"errors/position_m/{branch}",
            indexes=times,
            columns=rr.Scalars.columns(scalars=error_xy),
        )
        rec.send_columns(
            f"errors/heading_rad/{branch}",
            indexes=times,
            columns=rr.Scalars.columns(scalars=error_theta),
        )


def covariance_ellipses(centres: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """Closed outlines ``(S, ELLIPSE_POINTS, 2)`` of the ``ELLIPSE_SIGMA`` ellipses of the
    position covariances ``cov (S, 2, 2)`` about ``centres (S, 2)``:
    ``c + ELLIPSE_SIGMA * L u`` for ``u`` round the unit circle, ``L L^T = cov``."""
    angle = np.linspace(0.0, 2.0 * np.pi, ELLIPSE_POINTS)
    circle = np.stack([np.cos(angle), np.sin(angle)], axis=-1)  # (A, 2)
    values, vectors = np.linalg.eigh(cov)
    root = vectors * np.sqrt(np.clip(values, 0.0, None))[:, None, :]  # (S, 2, 2), root root^T = cov
    return centres[:, None, :] + ELLIPSE_SIGMA * circle @ root.mT


def record_interval_sets(rec: rr.RecordingStream, epochs: EpochLog) -> None:
    """The outer boxes and hull of every epoch, and the per-epoch figures as time series."""
    if len(epochs.t_s) == 0:
        return
    times = [rr.TimeColumn(TIMELINE, duration=epochs.t_s)]
    boxes = epochs.boxes
    centres = 0.5 * (boxes[:, :2, 0] + boxes[:, :2, 1])
    half = 0.5 * (boxes[:, :2, 1] - boxes[:, :2, 0])
    colors = np.where(epochs.inner[:, None], INNER_BOX_COLOR, BOX_COLOR).astype(np.uint8)
    rec.send_columns(
        "world/intervals/boxes",
        indexes=times,
        columns=rr.Boxes2D.columns(centers=centres, half_sizes=half, colors=colors).partition(
            epochs.box_counts
        ),
    )
    has_set = epochs.has_set
    hull = np.where(has_set[:, None, None], epochs.hull, 0.0)
    rec.send_columns(
        "world/intervals/hull",
        indexes=times,
        columns=rr.Boxes2D.columns(
            centers=0.5 * (hull[has_set, :2, 0] + hull[has_set, :2, 1]),
            half_sizes=0.5 * (hull[has_set, :2, 1] - hull[has_set, :2, 0]),
        ).partition(has_set.astype(np.int64)),
    )
    rec.log(
        "world/intervals/hull", rr.Boxes2D.from_fields(colors=HULL_COLOR, radii=0.01), static=True
    )
    width = np.max(epochs.hull[:, :2, 1] - epochs.hull[:, :2, 0], axis=1)
    series = {
        "intervals/box_width_m": width,
        "intervals/area_m2": epochs.area_m2,
        "intervals/q_used": epochs.q_used.astype(np.float64),
        "intervals/epoch_ms": epochs.elapsed_s * 1e3,
        "intervals/status": epochs.status.astype(np.float64),
    }
    for entity, values in series.items():
        rec.send_columns(entity, indexes=times, columns=rr.Scalars.columns(scalars=values))
