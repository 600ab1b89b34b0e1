"""Path following and command limits."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from robotsim.control import Route, ScriptedProfile, limit_command, speed_limited
from robotsim.errors import RobotsimError
from robotsim.maps import builtin_map, point_segment_distance
from robotsim.robot import RobotParams
from robotsim.simulation import simulate

ROBOT = RobotParams()


def test_pure_pursuit_visits_every_waypoint_and_stops_at_the_last():
    waypoints = np.array([[4.5, 1.0], [8.8, 1.0], [8.8, 4.0], [4.5, 4.0], [4.5, 7.0], [1.0, 7.0]])
    route = Route(waypoints, cruise_speed_m_s=0.4, lookahead_m=0.4)
    log = simulate(
        builtin_map("hall"),
        route,
        start_pose=(1.0, 1.0, 0.5),
        duration_s=80.0,
        rng=np.random.default_rng(0),
    )
    distance = np.linalg.norm(log.pose[:, None, :2] - waypoints, axis=2)
    assert distance.min(axis=0).max() < 0.25  # corners are cut by less than the lookahead
    first_visit = distance.argmin(axis=0)
    assert np.all(np.diff(first_visit) > 0)  # in order
    assert distance[-1, -1] <= route.goal_tolerance_m + 0.02
    np.testing.assert_allclose(log.velocity[-50:], 0.0, atol=1e-3)
    # it stays near the path between the waypoints
    path = np.vstack([[1.0, 1.0], waypoints])
    off_path = point_segment_distance(log.pose[:, None, :2], path[:-1], path[1:]).min(axis=1)
    assert off_path.max() < 0.4


def test_looping_route_keeps_going_round():
    waypoints = np.array([[2.0, 1.0], [6.0, 1.0], [6.0, 4.0], [2.0, 4.0]])
    route = Route(waypoints, loop=True)
    log = simulate(
        builtin_map("hall"),
        route,
        start_pose=(2.0, 1.0, 0.0),
        duration_s=90.0,
        rng=np.random.default_rng(0),
    )
    near_start = np.linalg.norm(log.pose[:, :2] - waypoints[0], axis=1) < 0.2
    arrivals = np.count_nonzero(np.diff(near_start.astype(int)) == 1)
    assert arrivals >= 2  # one lap of 14 m takes about 40 s
    assert np.abs(log.velocity[-100:, 0]).min() > 0.1


@pytest.mark.parametrize(
    "waypoints",
    [
        [[0.9, 1.0], [0.9, 1.0], [0.9, 1.0]],  # a loop of one point, the start: zero length
        [[1.0, 1.0], [1.5, 1.0], [1.5, 1.5]],  # a loop of 1.7 m, all within the lookahead
    ],
)
def test_a_loop_within_the_lookahead_gives_a_command(waypoints):
    """Regression (found by tests/scenarios/test_fuzz.py): with every waypoint of a looping
    route within the lookahead of the robot, the segment search went round the loop forever;
    a command now looks at most one lap ahead."""
    from robotsim.control import PurePursuit

    route = Route(np.array(waypoints), loop=True, lookahead_m=16.0)
    controller = PurePursuit(route, RobotParams())
    for k in range(20):
        v, omega = controller.command(0.1 * k, 0.9, 1.0 + 0.01 * k, 0.0)
        assert np.isfinite(v) and np.isfinite(omega)


def test_a_route_starting_behind_the_robot_turns_in_place_first():
    route = Route([[2.0, 4.0]])
    log = simulate(
        builtin_map("hall"),
        route,
        start_pose=(5.0, 4.0, 0.0),
        duration_s=20.0,
        rng=np.random.default_rng(0),
    )
    assert log.pose[:, 0].max() < 5.05  # it never drove away from the goal
    assert np.hypot(*(log.pose[-1, :2] - [2.0, 4.0])) < 0.1


def test_scripted_profile_holds_each_command_and_is_zero_before_it():
    controller = ScriptedProfile([1.0, 2.0], [0.3, -0.1], [0.2, 0.0]).controller(ROBOT)
    assert controller.command(0.5, 0, 0, 0) == (0.0, 0.0)
    assert controller.command(1.0, 0, 0, 0) == (0.3, 0.2)
    assert controller.command(1.99, 0, 0, 0) == (0.3, 0.2)
    assert controller.command(50.0, 0, 0, 0) == (-0.1, 0.0)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.floats(-5, 5), st.floats(-5, 5)), min_size=1, max_size=40))
def test_limited_commands_respect_speed_and_acceleration_limits(wanted):
    dt_s = 0.01
    previous = (0.0, 0.0)
    for v, omega in wanted:
        limited = limit_command(v, omega, previous, dt_s, ROBOT)
        assert abs(limited[0]) <= ROBOT.v_max_m_s and abs(limited[1]) <= ROBOT.omega_max_rad_s
        assert abs(limited[0] - previous[0]) <= ROBOT.a_max_m_s2 * dt_s + 1e-12
        assert abs(limited[1] - previous[1]) <= ROBOT.alpha_max_rad_s2 * dt_s + 1e-12
        # the limit moves as far towards the wanted value as allowed
        if abs(v) <= ROBOT.v_max_m_s and abs(v - previous[0]) < ROBOT.a_max_m_s2 * dt_s - 1e-12:
            assert limited[0] == v
        previous = limited


@settings(max_examples=60, deadline=None)
@given(st.floats(-5, 5), st.floats(-5, 5), st.floats(1e-4, 0.1))
def test_a_ramp_that_reached_the_clamped_command_stays_there(v, omega, dt_s):
    # the simulator skips limit_command once the target is the clamped command: exact
    reached = speed_limited(v, omega, ROBOT)
    assert limit_command(v, omega, reached, dt_s, ROBOT) == reached
    assert abs(reached[0]) <= ROBOT.v_max_m_s and abs(reached[1]) <= ROBOT.omega_max_rad_s


def test_simulated_truth_respects_the_robot_limits():
    route = Route([[8.5, 1.0], [8.5, 7.0], [1.0, 7.0]], cruise_speed_m_s=1.0)  # asks too much
    log = simulate(
        builtin_map("hall"),
        route,
        start_pose=(1.0, 1.0, 1.0),
        duration_s=40.0,
        rng=np.random.default_rng(0),
    )
    assert np.abs(log.velocity[:, 0]).max() <= ROBOT.v_max_m_s + 1e-6
    assert np.abs(log.velocity[:, 1]).max() <= ROBOT.omega_max_rad_s + 1e-6
    acceleration = np.diff(log.velocity[:, 0]) * log.rate_hz
    assert np.abs(acceleration).max() <= ROBOT.a_max_m_s2 + 1e-3


@pytest.mark.parametrize(
    ("make", "words"),
    [
        (lambda: Route(np.zeros((0, 2))), "waypoints"),
        (lambda: Route([[0.0, np.nan]]), "finite"),
        (lambda: Route([[1.0, 1.0]], lookahead_m=0.0), "lookahead_m"),
        (lambda: Route([[1.0, 1.0]], loop=True), "2 waypoints"),
        (lambda: ScriptedProfile([1.0, 0.5], [0.1, 0.1], [0.0, 0.0]), "increasing"),
        (lambda: ScriptedProfile([1.0], [0.1, 0.2], [0.0]), "shape"),
    ],
)
def test_bad_plans_are_refused(make, words):
    with pytest.raises(RobotsimError, match=words):
        make()
