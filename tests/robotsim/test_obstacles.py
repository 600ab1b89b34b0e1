"""Unmapped obstacles: their shapes are checked, their paths are where the docs put them,
the sonar sees them at the scan's time, and pymunk stops (or pushes) the robot at them."""

import numpy as np
import pytest
import shapely

from robotsim.control import ScriptedProfile
from robotsim.errors import RobotsimError
from robotsim.maps import builtin_map
from robotsim.obstacles import Obstacle, Obstacles
from robotsim.robot import RobotParams
from robotsim.sensors.sonar import SonarBeltParams, cone_distances
from robotsim.simulation import SensorSuite, SonarFailure, simulate
from robotsim.world import MOVER_BLOCK_STEPS, World

HALL = builtin_map("hall")
SQUARE = [[4.0, 4.0], [4.6, 4.0], [4.6, 4.6], [4.0, 4.6]]


@pytest.mark.parametrize(
    ("vertices", "polygon", "reason"),
    [
        ([[0, 0], [1, 1], [1, 0], [0, 1]], True, "not simple"),  # a bow tie
        ([[0, 0], [1, 0], [2, 0]], True, "not simple|degenerate"),  # no area
        ([[0, 0], [1, 0], [1, 0], [0, 1]], True, "degenerate"),  # a repeated vertex
        ([[0, 0], [1, 0]], True, "at least 3 vertices"),
        ([[0, 0], [np.nan, 0], [0, 1]], True, "finite"),
        ([[1, 1], [1, 1]], False, "zero length"),
        ([[0, 0], [1, 0], [2, 0]], False, "2 points"),
    ],
)
def test_bad_shapes_are_refused(vertices, polygon, reason):
    with pytest.raises(RobotsimError, match=reason):
        Obstacle(np.array(vertices, dtype=float), polygon=polygon)


def test_a_looping_path_without_waypoints_and_a_bad_speed_are_refused():
    with pytest.raises(RobotsimError, match="needs a path"):
        Obstacle(np.array(SQUARE), loop=True)
    with pytest.raises(RobotsimError, match="speed_m_s"):
        Obstacle(np.array(SQUARE), path_m=[[6, 4.3]], speed_m_s=0.0)


def test_the_path_is_walked_at_the_speed_from_the_centroid_and_loops_back():
    person = Obstacle(np.array(SQUARE), path_m=[[6.3, 4.3], [6.3, 6.3]], speed_m_s=0.5, loop=True)
    np.testing.assert_allclose(person.reference_m, [4.3, 4.3])
    # legs 2 m east, 2 m north, then back to the start (2 sqrt 2 m): 4 + 2.83 m a lap
    lap = 4.0 + 2.0 * np.sqrt(2.0)
    t = np.array([0.0, 2.0, 4.0, 6.0, 8.0 + np.sqrt(2.0) / 0.5, 2.0 * lap, 2.0 * lap + 2.0])
    expected = [[0, 0], [1, 0], [2, 0], [2, 1], [1, 1], [0, 0], [1, 0]]
    np.testing.assert_allclose(person.offset_m(t), expected, atol=1e-12)
    once = Obstacle(np.array(SQUARE), path_m=[[6.3, 4.3]], speed_m_s=0.5)
    np.testing.assert_allclose(once.offset_m([1.0, 4.0, 100.0]), [[0.5, 0], [2, 0], [2, 0]])
    # the sweep holds the shape wherever it goes, and nothing far from the path
    swept = person.swept()
    for time in np.linspace(0.0, lap / 0.5, 23):
        assert swept.buffer(1e-9).covers(person.geometry(time))
    assert not swept.intersects(shapely.Point(5.8, 4.8))  # inside the triangle the path rounds


def test_the_sonar_sees_a_static_obstacle_the_map_lacks():
    belt = SonarBeltParams.default_belt()
    wall = Obstacles((Obstacle(np.array([[6.0, 3.0], [6.0, 5.0]]), polygon=False),))
    pose = np.array([[4.0, 4.0, 0.0]])
    args = (belt.mount_xy, belt.mount_angle_rad, belt.half_aperture_rad)
    seen = wall.cone_distances(pose, [0.0], HALL.segments, *args)
    bare = cone_distances(pose, HALL.segments, *args)
    # the front sensor (on the rim at 0.2 m) faces the segment 2 m ahead: 1.8 m, not the map's
    assert seen[0, 0] == pytest.approx(1.8, abs=1e-12) and bare[0, 0] > 1.8 + 0.1
    # the others see the map, or the segment where it is nearer, exactly as the union does
    union = np.concatenate([HALL.segments, wall.static_edges_m])
    np.testing.assert_array_equal(seen, cone_distances(pose, union, *args))


def test_a_moving_obstacle_is_seen_where_it_is_at_each_scan():
    belt = SonarBeltParams.default_belt()
    person = Obstacle(np.array(SQUARE), path_m=[[6.3, 4.3]], speed_m_s=0.5, loop=True)
    world = Obstacles((person,))
    t = np.linspace(0.0, 12.0, 25)
    poses = np.column_stack([np.full(25, 2.0), np.full(25, 4.3), np.zeros(25)])
    args = (belt.mount_xy, belt.mount_angle_rad, belt.half_aperture_rad)
    got = world.cone_distances(poses, t, HALL.segments, *args)
    for i, time in enumerate(t):  # one scan at a time, the square moved by hand
        moved = person.edges_m() + person.offset_m(time)
        alone = cone_distances(poses[i], np.concatenate([HALL.segments, moved]), *args)
        np.testing.assert_array_equal(got[i], alone)
    # the front sensor sees the square's west face come and go: 4.0 - 2.2 m, then 2 m on
    front = 4.0 + person.offset_m(t)[:, 0] - 2.2
    np.testing.assert_allclose(got[:, 0], front, atol=1e-12)


def test_driving_into_an_unmapped_box_is_a_real_pymunk_contact():
    box = Obstacles((Obstacle(np.array([[6.0, 3.5], [6.6, 3.5], [6.6, 4.5], [6.0, 4.5]])),))
    drive = ScriptedProfile([0.0], [0.3], [0.0])
    log = simulate(
        HALL,
        drive,
        start_pose=(4.0, 4.0, 0.0),
        duration_s=15.0,
        rng=np.random.default_rng(0),
        obstacles=box,
    )
    # stopped by the box: the disk's front (radius 0.2, box faces 0.02 thick) at x = 6
    assert log.pose[-1, 0] == pytest.approx(6.0 - 0.2 - 0.02, abs=0.01)
    first = int(np.argmax(log.obstacle_contact))
    assert log.obstacle_contact.any() and log.obstacle_contact[first:-1].mean() > 0.9
    assert not log.wall_contact.any()  # the map's walls were never touched
    # the box is no wall of the map: without it the robot drives on
    free = simulate(
        HALL, drive, start_pose=(4.0, 4.0, 0.0), duration_s=15.0, rng=np.random.default_rng(0)
    )
    assert free.pose[-1, 0] > 7.0 and not free.obstacle_contact.any()


def test_a_moving_obstacle_pushes_a_robot_that_stands_in_its_way():
    slab = Obstacle(
        np.array([[2.0, 3.0], [2.3, 3.0], [2.3, 5.0], [2.0, 5.0]]), path_m=[[5.15, 4.0]]
    )
    log = simulate(
        HALL,
        ScriptedProfile([0.0], [0.0], [0.0]),
        start_pose=(4.0, 4.0, 0.0),
        duration_s=8.0,
        rng=np.random.default_rng(0),
        obstacles=Obstacles((slab,)),
    )
    # the slab's east face goes from x = 2.3 to 5.3 (3 m at 1 m/s): the robot is pushed ahead
    # of it, never through it (up to pymunk's collision slop), and slides a little on
    face = 2.3 + slab.offset_m(log.t_s)[:, 0]
    reach = 0.2 + 0.02  # the disk's radius and the faces' thickness
    assert log.obstacle_contact.any() and not log.obstacle_contact[:140].any()  # met at 1.48 s
    assert (log.pose[:, 0] - reach - face).min() > -0.01
    assert 5.3 + reach < log.pose[-1, 0] < 5.3 + reach + 0.1


def test_the_world_puts_each_moving_obstacle_on_its_path_at_every_step():
    """The world's moving bodies, computed a block of steps at a time, stand where the path
    has them at each step's time ``k / step_hz`` and move at the velocity reaching the next
    step's place, for more steps than one block (two movers, one looping)."""
    person = Obstacle(np.array(SQUARE), path_m=[[6.3, 4.3], [6.3, 6.3]], speed_m_s=0.5, loop=True)
    cart = Obstacle(np.array([[7.0, 2.0], [7.5, 2.0]]), polygon=False, path_m=[[7.25, 6.0]])
    world = World(HALL, RobotParams(), (2.0, 2.0, 0.0), obstacles=Obstacles((person, cart)))
    bodies = [body for _, body in world._movers]
    dt = world.dt_s
    for k in range(MOVER_BLOCK_STEPS + 300):
        t = k * dt
        for obstacle, body in zip((person, cart), bodies, strict=True):
            now, then = obstacle.offset_m(np.array([t, t + dt]))
            assert tuple(body.position) == tuple((obstacle.reference_m + now).tolist())
            assert tuple(body.velocity) == tuple(((then - now) / dt).tolist())
        world.step(0.0, 0.0)


def test_start_and_kidnap_poses_must_be_clear_of_the_obstacles_at_their_time():
    person = Obstacle(np.array(SQUARE), path_m=[[8.3, 4.3]], speed_m_s=1.0)
    obstacles = Obstacles((person,))
    with pytest.raises(RobotsimError, match="overlaps an obstacle at t = 0"):
        World(HALL, RobotParams(), (4.3, 4.3, 0.0), obstacles=obstacles)
    world = World(HALL, RobotParams(), (1.0, 1.0, 0.0), obstacles=obstacles)
    world.check_free((4.3, 4.3, 0.0), t_s=3.0)  # the person has walked on
    with pytest.raises(RobotsimError, match="at t = 3"):
        world.check_free((7.3, 4.3, 0.0), t_s=3.0)


def test_a_sonar_failure_replaces_the_failed_sensors_readings_in_its_window_only():
    sensors = SensorSuite(sonar=SonarBeltParams.default_belt(rate_hz=2.0))
    common = {"start_pose": (1.0, 1.0, 0.0), "duration_s": 10.0, "sensors": sensors}
    drive = ScriptedProfile([0.0], [0.3], [0.0])
    plain = simulate(HALL, drive, rng=np.random.default_rng(3), **common)
    stuck = SonarFailure(2.0, 4.5, (0, 5), reading_m=0.5)
    silent = SonarFailure(6.0, 7.0, tuple(range(16)))
    failed = simulate(
        HALL, drive, rng=np.random.default_rng(3), sonar_failures=(stuck, silent), **common
    )
    t = plain.sonar_t_s
    in_stuck, in_silent = (t >= 2.0) & (t < 4.5), (t >= 6.0) & (t < 7.0)
    assert in_stuck.sum() == 5 and in_silent.sum() == 2
    expected = plain.sonar_range_m.copy()
    expected[np.ix_(in_stuck, [0, 5])] = 0.5
    expected[in_silent] = np.inf
    np.testing.assert_array_equal(failed.sonar_range_m, expected)
    assert (
        failed.sonar_fault[np.ix_(in_stuck, [0, 5])].all() and failed.sonar_fault[in_silent].all()
    )
    np.testing.assert_array_equal(failed.pose, plain.pose)  # the motion is the same
    with pytest.raises(RobotsimError, match="not on the belt"):
        simulate(
            HALL,
            drive,
            rng=np.random.default_rng(3),
            sonar_failures=(SonarFailure(1, 2, (16,)),),
            **common,
        )
