"""Plain helpers shared by test modules: random sonar cases, the 60 m hall and the brute-force
counts of the readings a pose does not explain, that the modules' own case builders call (a
fixture cannot be called from a plain function, so these are functions). Fixtures live in
``tests/conftest.py``; no test module imports another
(``tests/test_import_direction.py``).
"""

from __future__ import annotations

import resource
import signal

import numpy as np
import shapely

from intervals.sonar.scan import SonarBelt, SonarScan
from robotsim.sensors.sonar import SonarBeltParams, cone_distances

#: The default 16-sonar belt (:meth:`SonarBeltParams.default_belt`).
DEFAULT_BELT = SonarBeltParams.default_belt()


def cone_ranges(
    poses: np.ndarray, segments: np.ndarray, params: SonarBeltParams = DEFAULT_BELT
) -> np.ndarray:
    """Exact ranges ``(..., k)`` in m from poses ``(..., 3)`` to the nearest wall in each
    sensor's cone (robotsim's model: the truth the interval tests must never lose)."""
    return cone_distances(
        poses, segments, params.mount_xy, params.mount_angle_rad, params.half_aperture_rad
    )


def bounded_readings(
    d: np.ndarray, params: SonarBeltParams, rng: np.random.Generator, extreme: bool = True
) -> np.ndarray:
    """Readings within their error bounds ``e_abs + e_rel d`` of the ranges ``d`` (``inf``
    beyond ``d_max``, never negative); with ``extreme`` half of the errors sit exactly on a
    bound, where an unsound test fails first."""
    bound = params.error_abs_bound_m + params.error_rel_bound * np.where(np.isfinite(d), d, 0)
    unit = rng.uniform(-1, 1, size=d.shape)
    if extreme:
        unit = np.where(rng.random(d.shape) < 0.5, np.sign(unit), unit)
    m = np.maximum(d + unit * bound, 0.0)
    return np.where(d > params.d_max_m, np.inf, m)


def random_room(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A 10 m x 10 m room with 3 to 10 random wall pieces inside: ``(segments (S, 2, 2),
    boundary polygon (4, 2))``, in m."""
    outer = np.array([[0, 0], [10, 0], [10, 10], [0, 10]], dtype=float)
    walls = np.stack([outer, np.roll(outer, -1, axis=0)], axis=1)
    start = rng.uniform(0.5, 9.5, size=(rng.integers(3, 11), 2))
    angle = rng.uniform(-np.pi, np.pi, size=len(start))
    length = rng.uniform(0.2, 3.0, size=len(start))
    end = np.clip(start + length[:, None] * np.stack([np.cos(angle), np.sin(angle)], 1), 0.1, 9.9)
    return np.concatenate([walls, np.stack([start, end], axis=1)]), outer


def boxes_around(truth: np.ndarray, rng: np.random.Generator, count: int) -> np.ndarray:
    """Boxes ``(count, 3, 2)`` that contain the pose ``truth (3,)``: widths from 1e-6 to 2 m
    and 1e-6 to 2 pi rad (log-uniform), a fifth of them with the truth on a face or corner."""
    w = np.exp(rng.uniform(np.log(1e-6), np.log(2.0), size=(count, 3)))
    w[:, 2] = np.exp(rng.uniform(np.log(1e-6), np.log(2 * np.pi), size=count))
    frac = rng.uniform(0, 1, size=(count, 3))
    frac[: count // 5] = rng.choice([0.0, 1.0], size=(count // 5, 3))  # truth on a face
    lo = truth - frac * w
    return np.stack([lo, np.maximum(lo + w, truth)], axis=-1)


BIG_HALL_BOUNDARY = np.array([[0.0, 0.0], [60.0, 0.0], [60.0, 60.0], [0.0, 60.0]])
"""The plain 60 m x 60 m hall of ``big_hall``: its boundary polygon ``(4, 2)`` in m."""
BIG_HALL_SEGMENTS = np.stack([BIG_HALL_BOUNDARY, np.roll(BIG_HALL_BOUNDARY, -1, axis=0)], axis=1)
"""Its four walls ``(4, 2, 2)`` in m."""


def big_hall_truth(rng: np.random.Generator, where: int) -> np.ndarray:
    """A random pose ``(x_m, y_m, theta_rad)`` in the 60 m hall: ``where`` 0 along the south
    wall far from the corners, 1 in the south-west corner, 2 in the open, out of every wall's
    reach."""
    if where == 0:
        return np.array([rng.uniform(10, 50), rng.uniform(0.5, 2.5), rng.uniform(-0.3, 0.3)])
    if where == 1:
        return np.array([*rng.uniform(0.5, 2.5, 2), rng.uniform(-np.pi, np.pi)])
    return np.array([*rng.uniform(10, 50, 2), rng.uniform(-np.pi, np.pi)])


def big_hall_scan(
    readings: np.ndarray, echoes_never_lost: bool = False, params: SonarBeltParams = DEFAULT_BELT
) -> SonarScan:
    """The scan of ``readings (k,)`` in m by the belt ``params`` in the 60 m hall."""
    belt = SonarBelt.from_params(params, echoes_never_lost=echoes_never_lost)
    return SonarScan(BIG_HALL_SEGMENTS, belt, readings, BIG_HALL_BOUNDARY)


def wrong_echoes(poses: np.ndarray, scan: SonarScan, params: SonarBeltParams) -> np.ndarray:
    """``(...,)``: the echoes of ``scan`` the poses ``(..., 3)`` do not explain by the
    simulator's cone model within the error bounds (a no-echo reading is not counted)."""
    d = cone_ranges(poses, scan.segments, params)
    m = scan.readings_m
    with np.errstate(invalid="ignore"):  # inf - inf: no echo, not counted
        gap = np.abs(m - d)
    bound = params.error_abs_bound_m + params.error_rel_bound * np.where(np.isfinite(d), d, 0.0)
    explained = (d <= params.d_max_m) & (gap <= bound)
    return np.count_nonzero(np.isfinite(m) & ~explained, axis=-1)


def wrong_readings(poses: np.ndarray, scan: SonarScan, params: SonarBeltParams) -> np.ndarray:
    """``(...,)``: the readings the poses ``(..., 3)`` do not explain (:func:`wrong_echoes`), the
    no-echo readings included where they prove free space (``echoes_never_lost``: a wall in
    reach), and poses outside ``scan.boundary`` counted as explaining none (``k + 1``)."""
    wrong = wrong_echoes(poses, scan, params)
    if scan.belt.echoes_never_lost:
        d = cone_ranges(poses, scan.segments, params)
        free = ~np.isfinite(scan.readings_m)
        wrong = wrong + np.count_nonzero(free & (d <= params.d_max_m), axis=-1)
    room = shapely.contains_xy(shapely.Polygon(scan.boundary), poses[..., 0], poses[..., 1])
    return np.where(room, wrong, scan.belt.count + 1)


def with_outliers(scan: SonarScan, rng: np.random.Generator, count: int) -> SonarScan:
    """The scan with ``count`` readings replaced by uniform values in ``[0, d_max]``."""
    readings = scan.readings_m.copy()
    which = rng.choice(readings.size, size=count, replace=False)
    readings[which] = rng.uniform(0.0, scan.belt.d_max_m, count)
    return SonarScan(scan.segments, scan.belt, readings, scan.boundary)


_CORNERS = np.array(np.meshgrid([0, 1], [0, 1], [0, 1], indexing="ij")).reshape(3, -1).T
"""The corners of the unit cube ``(8, 3)``, as fractions of a box's widths."""


def sample_in_boxes(
    boxes: np.ndarray, truth: np.ndarray, rng: np.random.Generator, count: int
) -> np.ndarray:
    """Poses ``(N, count + 8 + 16, 3)`` in each of ``boxes (N, 3, 2)``: its corners, uniform
    draws and draws near ``truth (3,)`` (clipped to the box), where the consistent poses are."""
    lo, hi = boxes[:, :, 0], boxes[:, :, 1]
    frac = np.concatenate([_CORNERS, rng.uniform(0, 1, (count, 3))])
    uniform = lo[:, None] + frac[None] * (hi - lo)[:, None]
    uniform = np.clip(uniform, lo[:, None], hi[:, None])  # lo + (hi - lo) may round past hi
    near = truth + rng.normal(0, 1, (boxes.shape[0], 16, 3)) * np.array([0.03, 0.03, 0.02])
    near = np.clip(near, lo[:, None], hi[:, None])
    return np.concatenate([uniform, near], axis=1)


def small_file_limit(max_bytes: int):
    """A ``preexec_fn``: files may not grow beyond ``max_bytes`` (``ulimit -f``); the signal
    such a write raises is ignored, so the write fails with ``EFBIG`` as on a full disk."""

    def limit() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (max_bytes, max_bytes))

    return limit


def random_walled_room(rng):
    """A 10 m x 10 m room with 2 to 8 random wall pieces inside: ``(segments, boundary)``."""
    outer = np.array([[0, 0], [10, 0], [10, 10], [0, 10]], dtype=float)
    walls = np.stack([outer, np.roll(outer, -1, axis=0)], axis=1)
    start = rng.uniform(0.5, 9.5, size=(rng.integers(2, 9), 2))
    angle = rng.uniform(-np.pi, np.pi, size=len(start))
    if rng.random() < 0.5:  # axis-parallel walls take the exact path of eq. 2
        angle = np.round(angle / (np.pi / 2)) * (np.pi / 2)
    length = rng.uniform(0.2, 3.0, size=len(start))
    end = np.clip(start + length[:, None] * np.stack([np.cos(angle), np.sin(angle)], 1), 0.1, 9.9)
    return np.concatenate([walls, np.stack([start, end], axis=1)]), outer


def random_belt(rng, gamma):
    """The default 16-sonar belt, or 8 sensors with random mounts and axes (not radial)."""
    if rng.random() < 0.5:
        return SonarBeltParams.default_belt(
            half_aperture_rad=gamma, d_max_m=rng.choice([3.0, 100.0])
        )
    mounts = rng.uniform(-0.3, 0.3, size=(8, 2))
    return SonarBeltParams(
        mount_xy=mounts,
        mount_angle_rad=rng.uniform(-np.pi, np.pi, 8),
        half_aperture_rad=gamma,
        d_max_m=rng.choice([3.0, 100.0]),
    )


def random_scan_case(rng, gamma, echoes_never_lost):
    """A random map, belt, true pose (0.3 m clear of walls) and its scan."""
    segments, outer = random_walled_room(rng)
    params = random_belt(rng, gamma)
    while True:
        truth = np.array([*rng.uniform(0.3, 9.7, 2), rng.uniform(-np.pi, np.pi)])
        a, e = segments[:, 0], segments[:, 1] - segments[:, 0]
        t = np.clip(np.sum((truth[:2] - a) * e, 1) / np.sum(e * e, 1), 0, 1)
        if np.min(np.hypot(*(a + t[:, None] * e - truth[:2]).T)) > 0.3:
            break
    belt = SonarBelt.from_params(params, echoes_never_lost=echoes_never_lost)
    readings = bounded_readings(cone_ranges(truth, segments, params), params, rng)
    return SonarScan(segments, belt, readings, outer), params, truth


def circuit_poses(epochs: int) -> np.ndarray:
    """Poses ``(epochs, 3)`` at 1 s intervals on a circle of radius 2 m at 0.3 m/s (CCW)."""
    omega = 0.3 / 2.0
    t = np.arange(epochs, dtype=float)
    heading = np.mod(omega * t + np.pi / 2 + np.pi, 2 * np.pi) - np.pi
    return np.stack([4.5 + 2.0 * np.cos(omega * t), 3.8 + 2.0 * np.sin(omega * t), heading], 1)


def recording_columns(path) -> dict:
    """A ``.rrd`` recording read back: per ``(entity path, is static)``, its columns (without
    row ids) merged over its chunks, each the list of its rows (times in nanoseconds)."""
    import pyarrow as pa
    from rerun.chunk import RrdReader

    reader = RrdReader(path)
    data: dict = {}
    for chunk in reader.stream(store=reader.recordings()[0]):
        batch = chunk.to_record_batch()
        merged = data.setdefault((chunk.entity_path, chunk.is_static), {})
        for name in batch.schema.names:
            if name == "rerun.controls.RowId":
                continue
            column = batch.column(name)
            if pa.types.is_duration(column.type) or pa.types.is_timestamp(column.type):
                column = column.cast(pa.int64())  # nanoseconds
            merged.setdefault(name, []).extend(column.to_pylist())
    return data


def annotation_labels(data: dict) -> set[str]:
    """The class labels of the annotation context on ``/world`` of :func:`recording_columns`."""
    ((context,),) = data[("/world", True)]["AnnotationContext:context"]  # one row, one instance
    return {entry["class_description"]["info"]["label"] for entry in context}
