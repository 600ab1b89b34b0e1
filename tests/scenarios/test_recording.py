"""The geometry drawn in the recording: cones and echo points, checked against the readings."""

from __future__ import annotations

import numpy as np

from scenarios.recording import CONE_ARC_POINTS, cone_outlines, echo_points


def belt(k: int = 8, radius_m: float = 0.2):
    angle = np.linspace(-np.pi, np.pi, k, endpoint=False)
    return radius_m * np.stack([np.cos(angle), np.sin(angle)], axis=1), angle


def test_cone_outlines_reach_the_reading_inside_the_aperture():
    rng = np.random.default_rng(3)
    mount_xy, mount_angle = belt()
    poses = np.column_stack(
        [rng.uniform(0, 5, 20), rng.uniform(0, 5, 20), rng.uniform(-np.pi, np.pi, 20)]
    )
    ranges = rng.uniform(0.3, 3.2, (20, 8))
    ranges[rng.random((20, 8)) < 0.3] = np.inf
    gamma, d_max = np.radians(12.5), 3.0
    outline = cone_outlines(poses, ranges, mount_xy, mount_angle, gamma, d_max)
    assert outline.shape == (20, 8, CONE_ARC_POINTS + 2, 2)

    # the apex is the sensor in the world: (x, y) + R(theta) mount
    c, s = np.cos(poses[:, 2, None]), np.sin(poses[:, 2, None])
    apex = np.stack(
        [
            poses[:, 0, None] + c * mount_xy[:, 0] - s * mount_xy[:, 1],
            poses[:, 1, None] + s * mount_xy[:, 0] + c * mount_xy[:, 1],
        ],
        axis=-1,
    )
    np.testing.assert_allclose(outline[:, :, 0], apex)
    np.testing.assert_allclose(outline[:, :, -1], apex)  # closed
    arc = outline[:, :, 1:-1] - apex[:, :, None]
    reach = np.where(np.isfinite(ranges), ranges, d_max)
    np.testing.assert_allclose(
        np.linalg.norm(arc, axis=-1), np.broadcast_to(reach[..., None], arc.shape[:-1])
    )
    axis = poses[:, 2, None] + mount_angle
    offset = np.angle(np.exp(1j * (np.arctan2(arc[..., 1], arc[..., 0]) - axis[..., None])))
    np.testing.assert_allclose(offset[..., 0], -gamma, atol=1e-9)
    np.testing.assert_allclose(offset[..., -1], gamma, atol=1e-9)


def test_echo_points_lie_on_the_axis_at_the_reading():
    mount_xy, mount_angle = belt(4)
    poses = np.array([[1.0, 2.0, 0.3], [4.0, 1.0, -2.0]])
    ranges = np.array([[1.0, np.inf, 2.0, 0.5], [np.inf, np.inf, 3.0, np.inf]])
    points, counts = echo_points(poses, ranges, mount_xy, mount_angle)
    assert counts.tolist() == [3, 1] and points.shape == (4, 2)
    # sensor 0 of pose 0: mount (0.2 at -pi) behind the robot, pointing backwards
    heading = 0.3 + mount_angle[0]
    sensor = np.array([1.0, 2.0]) + 0.2 * np.array([np.cos(heading), np.sin(heading)])
    np.testing.assert_allclose(
        points[0], sensor + 1.0 * np.array([np.cos(heading), np.sin(heading)])
    )
    assert np.isfinite(points).all()


def test_covariance_ellipses_are_the_sigma_contours():
    from scenarios.recording import ELLIPSE_POINTS, ELLIPSE_SIGMA, covariance_ellipses

    rng = np.random.default_rng(1)
    a = rng.normal(size=(6, 2, 2))
    cov = a @ a.mT + 1e-3 * np.eye(2)
    centres = rng.uniform(0, 5, (6, 2))
    outline = covariance_ellipses(centres, cov)
    assert outline.shape == (6, ELLIPSE_POINTS, 2)
    d = outline - centres[:, None, :]
    mahalanobis = np.einsum("spi,sij,spj->sp", d, np.linalg.inv(cov), d)
    np.testing.assert_allclose(mahalanobis, ELLIPSE_SIGMA**2, rtol=1e-9)
    np.testing.assert_allclose(outline[:, 0], outline[:, -1])  # closed


#: Entities whose values are wall-clock measurements (not part of the determinism).
WALL_CLOCK_ENTITIES = ("/intervals/epoch_ms",)


def logged_data(path) -> dict:
    """Every column of a recording read back, per entity path (static or not), without the
    per-run bookkeeping rerun adds (row ids, the recording's start time)."""
    import pyarrow as pa
    from rerun.chunk import RrdReader

    def values(column: pa.Array) -> list:
        if pa.types.is_duration(column.type) or pa.types.is_timestamp(column.type):
            column = column.cast(pa.int64())  # nanoseconds, exactly
        return column.to_pylist()

    data: dict = {}
    for chunk in RrdReader(path).store().stream():
        batch = chunk.to_record_batch()
        columns = {
            name: values(batch.column(name))
            for name in batch.schema.names
            if name != "rerun.controls.RowId" and not name.startswith("RecordingInfo:")
        }
        data.setdefault((chunk.entity_path, chunk.is_static), []).append((batch.num_rows, columns))
    return data


def test_same_scenario_and_seed_log_the_same_data(tmp_path):
    """Determinism covers the logged data: entity paths, row counts and values are equal
    (the .rrd bytes differ: rerun stamps each recording with fresh ids and times), except
    the measured time per interval epoch."""
    from scenarios.recording import write_recording
    from scenarios.runner import run_scenario
    from scenarios.spec import load_scenario

    spec = load_scenario("hall").with_run(duration_s=3.0)
    paths = []
    for name, seed in (("a", 0), ("b", 0), ("c", 1)):
        run_spec = spec.with_run(seed=seed)
        result = run_scenario(run_spec)
        paths.append(tmp_path / f"{name}.rrd")
        write_recording(paths[-1], run_spec, result.log, result.estimation)
    first, second, other_seed = (logged_data(path) for path in paths)
    assert ("/world/robot/footprint", False) in first and len(first) > 20
    assert first.keys() == second.keys()
    for key in first:
        if key[0] not in WALL_CLOCK_ENTITIES:
            assert first[key] == second[key], key
        else:  # same rows and times, measured durations
            assert [(rows, c["time"]) for rows, c in first[key]] == [
                (rows, c["time"]) for rows, c in second[key]
            ]
    assert first != other_seed  # the comparison sees a change of the sensor noise
