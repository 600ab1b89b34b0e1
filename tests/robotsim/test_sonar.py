"""The exact sonar cone model against brute force, and the simulated readings."""

import numpy as np
import pytest

from robotsim.errors import RobotsimError
from robotsim.sensors import sonar
from robotsim.sensors.sonar import SonarBeltParams, cone_distances, simulate_readings


def brute_force_cone_distances(poses, segments, mount_xy, mount_angle_rad, gamma):
    """Sample the segments densely (keeping points inside the cone, by atan2) and cast rays
    across the cone (edges included); the minimum distance over both sample sets."""
    poses = np.asarray(poses)
    c, s = np.cos(poses[:, 2, None]), np.sin(poses[:, 2, None])
    apex = np.stack(
        [
            poses[:, 0, None] + c * mount_xy[:, 0] - s * mount_xy[:, 1],
            poses[:, 1, None] + s * mount_xy[:, 0] + c * mount_xy[:, 1],
        ],
        axis=-1,
    )[:, :, None, None, :]  # (n, k, 1, 1, 2)
    axis = (poses[:, 2, None] + mount_angle_rad)[:, :, None, None]  # (n, k, 1, 1)
    a, b = segments[:, 0], segments[:, 1]

    # points along the segments: (n, k, m, P)
    t = np.linspace(0.0, 1.0, 1501)
    offset = a[:, None, :] + t[:, None] * (b - a)[:, None, :] - apex
    bearing = np.arctan2(offset[..., 1], offset[..., 0]) - axis
    bearing = (bearing + np.pi) % (2 * np.pi) - np.pi
    distance = np.hypot(offset[..., 0], offset[..., 1])
    inside = (np.abs(bearing) <= gamma) | (distance == 0.0)
    from_points = np.where(inside, distance, np.inf).min(axis=(-1, -2))

    # rays across the cone: (n, k, m, R)
    phi = axis + np.linspace(-gamma, gamma, 1501)
    u_x, u_y = np.cos(phi), np.sin(phi)
    e_x, e_y = (b - a)[:, 0, None], (b - a)[:, 1, None]  # (m, 1)
    w_x, w_y = a[:, 0, None] - apex[..., 0], a[:, 1, None] - apex[..., 1]  # (n, k, m, 1)
    det_ue = u_x * e_y - u_y * e_x
    with np.errstate(divide="ignore", invalid="ignore"):
        rho = (w_x * e_y - w_y * e_x) / det_ue
        tau = (w_x * u_y - w_y * u_x) / det_ue
    hit = (rho >= 0) & (tau >= 0) & (tau <= 1) & np.isfinite(rho)
    from_rays = np.where(hit, rho, np.inf).min(axis=(-1, -2))
    return np.minimum(from_points, from_rays)


def random_segments(rng, count, near):
    """Random segments, some short, some long, some crossing the region of the sensors."""
    centre = near + rng.uniform(-3.0, 3.0, size=(count, 2))
    length = rng.choice([0.05, 0.5, 2.0, 6.0], size=count) * rng.uniform(0.2, 1.0, size=count)
    angle = rng.uniform(-np.pi, np.pi, size=count)
    half = 0.5 * length[:, None] * np.stack([np.cos(angle), np.sin(angle)], axis=1)
    return np.stack([centre - half, centre + half], axis=1)


@pytest.mark.slow
def test_cone_distance_matches_brute_force_sampling():
    rng = np.random.default_rng(20261122)
    cases = 0
    for _ in range(12):
        gamma = rng.uniform(0.02, 1.45)
        segments = random_segments(rng, 5, near=np.zeros(2))
        poses = np.column_stack(
            [rng.uniform(-2.5, 2.5, size=(60, 2)), rng.uniform(-np.pi, np.pi, size=60)]
        )
        mount_angle = rng.uniform(-np.pi, np.pi, size=4)
        mount_xy = rng.uniform(-0.3, 0.3, size=(4, 2))
        exact = cone_distances(poses, segments, mount_xy, mount_angle, gamma)
        sampled = brute_force_cone_distances(poses, segments, mount_xy, mount_angle, gamma)
        assert exact.shape == (60, 4)
        np.testing.assert_array_equal(np.isinf(exact), np.isinf(sampled))
        finite = np.isfinite(exact)
        # sampling only finds points of the cone, so never below the exact minimum ...
        assert (sampled[finite] >= exact[finite] - 1e-9).all()
        # ... and its dense samples come close to it
        assert (sampled[finite] - exact[finite] <= 2e-3).all()
        cases += exact.size
    assert cases >= 2000 and np.isfinite(exact).any()


def test_known_geometry():
    wall = np.array([[[2.0, -50.0], [2.0, 50.0]]])  # the line x = 2
    mount_xy = np.zeros((3, 2))
    mount_angle = np.array([0.0, np.pi, np.pi / 2])
    gamma = np.deg2rad(10.0)
    got = cone_distances([0.0, 0.0, 0.0], wall, mount_xy, mount_angle, gamma)
    # facing the wall: the foot of the perpendicular; facing away: inf;
    # facing along it: the cone edge reaches it at 2 / sin(gamma)
    np.testing.assert_allclose(got, [2.0, np.inf, 2.0 / np.sin(gamma)])
    # a short segment off-axis inside the cone: its nearer end point
    piece = np.array([[[3.0, 0.1], [4.0, 0.2]]])
    np.testing.assert_allclose(
        cone_distances([0.0, 0.0, 0.0], piece, mount_xy[:1], mount_angle[:1], gamma),
        [np.hypot(3.0, 0.1)],
    )


def test_batch_shape_and_pose_frame():
    wall = np.array([[[2.0, -5.0], [2.0, 5.0]], [[-5.0, 3.0], [5.0, 3.0]]])
    belt = SonarBeltParams.default_belt(robot_radius_m=0.2)
    poses = np.zeros((2, 5, 3))
    poses[..., 2] = np.linspace(-3.0, 3.0, 10).reshape(2, 5)
    got = cone_distances(poses, wall, belt.mount_xy, belt.mount_angle_rad, belt.half_aperture_rad)
    assert got.shape == (2, 5, 16)
    single = cone_distances(
        poses[1, 3], wall, belt.mount_xy, belt.mount_angle_rad, belt.half_aperture_rad
    )
    np.testing.assert_array_equal(got[1, 3], single)


def test_no_segments_means_no_echo_anywhere():
    got = cone_distances(np.zeros((4, 3)), np.zeros((0, 2, 2)), np.zeros((2, 2)), np.zeros(2), 0.2)
    assert got.shape == (4, 2) and np.isinf(got).all()


def test_bad_cone_arguments_are_refused():
    wall = np.array([[[2.0, -5.0], [2.0, 5.0]]])
    with pytest.raises(RobotsimError, match="half_aperture"):
        cone_distances([0, 0, 0], wall, np.zeros((1, 2)), np.zeros(1), 2.0)
    with pytest.raises(RobotsimError, match="poses"):
        cone_distances([0, 0], wall, np.zeros((1, 2)), np.zeros(1), 0.2)


def test_default_belt_is_sixteen_sensors_evenly_on_the_rim():
    belt = SonarBeltParams.default_belt(robot_radius_m=0.25)
    assert belt.count == 16
    np.testing.assert_allclose(np.linalg.norm(belt.mount_xy, axis=1), 0.25)
    steps = np.diff(np.sort(belt.mount_angle_rad))
    np.testing.assert_allclose(steps, 2 * np.pi / 16)
    assert (belt.mount_angle_rad >= -np.pi).all() and (belt.mount_angle_rad < np.pi).all()
    assert belt.d_max_m == 3.0 and belt.outlier_prob == 0.0 and belt.lost_echo_prob == 0.0


@pytest.mark.parametrize(
    ("settings", "words"),
    [
        ({"d_max_m": -1.0}, "d_max_m"),
        ({"error_rel_bound": 1.0}, "error_rel_bound"),
        ({"rate_hz": 0.0}, "rate_hz"),
        ({"outlier_prob": 1.5}, "outlier_prob"),
        ({"half_aperture_rad": 0.0}, "half_aperture_rad"),
    ],
)
def test_bad_belt_settings_are_refused(settings, words):
    with pytest.raises(RobotsimError, match=words):
        SonarBeltParams.default_belt(**settings)


def test_readings_respect_the_error_bound_and_range_limit():
    belt = SonarBeltParams.default_belt(error_abs_bound_m=0.03, error_rel_bound=0.02)
    rng = np.random.default_rng(5)
    d = np.concatenate([rng.uniform(0.0, 4.0, size=(20000, 16)), np.full((1, 16), np.inf)])
    readings, fault = simulate_readings(d, belt, rng)
    assert not fault.any()
    echo = d <= belt.d_max_m
    np.testing.assert_array_equal(np.isinf(readings), ~echo)
    bound = belt.error_abs_bound_m + belt.error_rel_bound * d[echo]
    error = readings[echo] - d[echo]
    assert (np.abs(error) <= bound + 1e-12).all()
    # the errors fill the bound (uniform), not a narrower band
    assert np.abs(error / bound).max() > 0.99
    # the interval of the contract holds the truth for every reading
    lower = (readings[echo] - belt.error_abs_bound_m) / (1 + belt.error_rel_bound)
    upper = (readings[echo] + belt.error_abs_bound_m) / (1 - belt.error_rel_bound)
    assert ((lower <= d[echo] + 1e-12) & (d[echo] <= upper + 1e-12)).all()


def test_fault_rates_match_their_probabilities():
    belt = SonarBeltParams.default_belt(outlier_prob=0.1, lost_echo_prob=0.05)
    rng = np.random.default_rng(6)
    d = rng.uniform(0.5, 2.5, size=(20000, 16))  # all echoes
    readings, fault = simulate_readings(d, belt, rng)
    lost = np.isinf(readings)
    assert np.all(fault[lost])
    n = d.size
    assert abs(lost.mean() - 0.05) < 4 * np.sqrt(0.05 * 0.95 / n)
    outlier = fault & ~lost
    expected = 0.95 * 0.1
    assert abs(outlier.mean() - expected) < 4 * np.sqrt(expected / n)
    assert readings[outlier].min() >= 0.0 and readings[outlier].max() <= belt.d_max_m
    # good readings keep their bound
    good = ~fault
    assert (np.abs(readings[good] - d[good]) <= 0.02 + 0.01 * d[good] + 1e-12).all()


def test_turning_faults_on_leaves_the_fault_free_readings_unchanged():
    d = np.random.default_rng(7).uniform(0.5, 2.5, size=(100, 16))
    clean, _ = simulate_readings(d, SonarBeltParams.default_belt(), np.random.default_rng(8))
    faulty, fault = simulate_readings(
        d, SonarBeltParams.default_belt(outlier_prob=0.2), np.random.default_rng(8)
    )
    assert fault.any()
    np.testing.assert_array_equal(clean[~fault], faulty[~fault])


def _segment_by_segment(poses, segments, *args):
    """The cone distances as the minimum of one-segment maps (each computed whole)."""
    return np.min(
        [cone_distances(poses, segments[j : j + 1], *args) for j in range(len(segments))], axis=0
    )


@pytest.mark.parametrize("layout", ["clutter", "far"])
def test_a_large_map_looked_at_nearest_first_gives_the_whole_maps_distances(layout, monkeypatch):
    """Maps above LARGE_MAP_SEGMENTS take the nearest-first path; its distances equal the
    minimum over one-segment maps bit for bit, both where the nearest segments settle most
    cones (clutter in a room) and where most cones look past them (a far cluster and nothing
    else: far echoes and none, computed again over the whole map)."""
    rng = np.random.default_rng(11 if layout == "clutter" else 12)
    room = np.array(
        [[[0, 0], [40, 0]], [[40, 0], [40, 40]], [[40, 40], [0, 40]], [[0, 40], [0, 0]]]
    )
    if layout == "clutter":
        centres = rng.uniform(0.0, 12.0, (300, 2))
        poses = np.column_stack([rng.uniform(1, 11, (40, 2)), rng.uniform(-4, 4, 40)])
        walls = room.astype(float)
    else:
        centres = rng.uniform(0.0, 3.0, (300, 2))
        poses = np.column_stack([rng.uniform(20, 38, (40, 2)), rng.uniform(-4, 4, 40)])
        walls = np.zeros((0, 2, 2))
    segments = np.concatenate([centres[:, None, :] + rng.uniform(-0.4, 0.4, (300, 2, 2)), walls])
    assert len(segments) > sonar.LARGE_MAP_SEGMENTS
    belt = SonarBeltParams.default_belt()
    args = (belt.mount_xy, belt.mount_angle_rad, belt.half_aperture_rad)
    settled, again = [], []  # cones computed among the nearest only, and over the whole map
    real = sonar._Cones.distances

    def counting(cones, index, a, e):
        (again if isinstance(index, tuple) else settled).append(
            len(index[0]) if isinstance(index, tuple) else a.shape[-2]
        )
        return real(cones, index, a, e)

    monkeypatch.setattr(sonar._Cones, "distances", counting)
    got = cone_distances(poses, segments, *args)
    monkeypatch.undo()
    assert settled == [sonar.NEAR_SEGMENTS] and sum(again) > 0
    if layout == "clutter":
        assert sum(again) < 0.2 * got.size
    else:
        assert sum(again) > 0.5 * got.size
    np.testing.assert_array_equal(got, _segment_by_segment(poses, segments, *args))
