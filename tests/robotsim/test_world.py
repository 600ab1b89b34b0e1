"""The pymunk world: free-space motion follows the true-radii kinematics, walls stop the
robot, kidnaps move it without odometry."""

import numpy as np
import pytest

from robotsim.control import ScriptedProfile
from robotsim.errors import RobotsimError
from robotsim.maps import builtin_map, point_segment_distance
from robotsim.robot import RobotParams, body_velocity, integrate_pose, wheel_rates, wrap_angle
from robotsim.simulation import KidnapEvent, simulate
from robotsim.world import World, WorldParams

ROBOT = RobotParams(true_wheel_radius_left_m=0.0508, true_wheel_radius_right_m=0.0495)


def run(profile, start, duration_s, the_map="hall", **settings):
    return simulate(
        builtin_map(the_map),
        profile,
        start_pose=start,
        duration_s=duration_s,
        rng=np.random.default_rng(0),
        robot=ROBOT,
        **settings,
    )


def test_free_space_motion_follows_commanded_wheel_speeds_with_true_radii():
    # constant commands held long after the acceleration ramp
    t_s = [0.0, 4.0, 8.0]
    v = [0.3, 0.2, 0.25]
    omega = [0.0, 0.4, -0.3]
    log = run(ScriptedProfile(t_s, v, omega), (5.0, 4.0, 0.3), 12.0)
    wheels = wheel_rates(np.column_stack([v, omega]), ROBOT.nominal_radii_m, ROBOT.wheel_base_m)
    expected_velocity = body_velocity(wheels, ROBOT.true_radii_m, ROBOT.wheel_base_m)
    assert not np.allclose(expected_velocity, np.column_stack([v, omega]), atol=1e-3)
    for start_s, (v_true, omega_true) in zip([2.0, 6.0, 10.0], expected_velocity, strict=True):
        window = slice(int(start_s * 100), int((start_s + 2.0) * 100) + 1)
        np.testing.assert_allclose(log.velocity[window], [[v_true, omega_true]] * 201, atol=1e-6)
        # the pose moves along the arc of the true-radii kinematics
        first = log.pose[window][0]
        arc = integrate_pose(first, [v_true, omega_true], 2.0)
        np.testing.assert_allclose(log.pose[window][-1, :2], arc[:2], atol=1e-4)
        assert abs(wrap_angle(log.pose[window][-1, 2] - arc[2])) < 1e-4


@pytest.mark.parametrize("heading", [0.0, 0.4, -0.7])
def test_robot_driven_into_a_wall_stops_at_it(heading):
    # symmetric map (8 m x 6 m): drive at full speed towards the east wall x = 8 for 10 s
    the_map = builtin_map("symmetric")
    profile = ScriptedProfile([0.0], [ROBOT.v_max_m_s], [0.0])
    log = run(profile, (5.0, 3.0, heading), 10.0, the_map="symmetric")
    contact_m = ROBOT.radius_m + WorldParams().wall_radius_m
    clearance = point_segment_distance(
        log.pose[:, None, :2], the_map.segments[:, 0], the_map.segments[:, 1]
    ).min(axis=1)
    # never through a wall: discrete contacts allow one step of motion plus the slop
    overlap_m = ROBOT.v_max_m_s / WorldParams().step_hz + WorldParams().collision_slop_m
    assert clearance.min() >= contact_m - overlap_m
    assert clearance[-100:].max() <= contact_m + 2e-3  # it reached a wall and stays there
    if heading == 0.0:  # head-on: pressed against the wall, it cannot move towards it
        x_speed = np.diff(log.pose[-100:, 0]) * log.rate_hz
        assert np.abs(x_speed).max() < 1e-3


def test_wall_contact_callback_fires_only_while_the_robot_touches_a_wall():
    # hall: east wall at x = 10; driven east from x = 9, then stopped after 3 s
    world = World(builtin_map("hall"), ROBOT, (9.0, 3.5, 0.0))
    contacts: list[int] = []  # the step of each solved contact
    world.on_wall_contact(lambda: contacts.append(step))
    gap_m = []  # distance from the disk's edge (plus the wall's radius) to the wall, per step
    for step in range(400):
        world.step(0.5 if step < 300 else 0.0, 0.0)
        gap_m.append(10.0 - world.state()[0] - ROBOT.radius_m - WorldParams().wall_radius_m)
    assert contacts
    first = min(contacts)
    assert gap_m[first] < 2e-3 and min(gap_m[: first - 1]) > 1e-3  # at the wall, not before
    assert set(range(first, 300)) <= set(contacts)  # every step while driven into it
    replaced: list[None] = []
    world.on_wall_contact(lambda: replaced.append(None))  # a later callback replaces the first
    count = len(contacts)
    world.step(0.5, 0.0)  # driven into the wall again
    assert replaced and len(contacts) == count
    free = World(builtin_map("hall"), ROBOT, (5.0, 3.5, 0.0))
    free_contacts: list[None] = []
    free.on_wall_contact(lambda: free_contacts.append(None))
    for _ in range(100):
        free.step(0.3, 0.2)
    assert not free_contacts  # nothing in free space


def test_the_step_path_moves_the_robot_as_pymunks_public_api_does():
    """World.step and World.state call pymunk's C functions directly; a world driven through
    pymunk's public properties and Space.step instead gives the same states, bit for bit
    (free motion, then pressed against hall's east wall, turning)."""
    fast = World(builtin_map("hall"), ROBOT, (8.5, 3.5, 0.1))
    public = World(builtin_map("hall"), ROBOT, (8.5, 3.5, 0.1))
    # the reference reaches into the world's pymunk objects: the public API on them
    body, control, space = public._body, public._control, public._space
    lead_s, substep_s = public._velocity_lead_s, public._substep_s
    contacts: list[int] = []
    fast.on_wall_contact(lambda: contacts.append(fast.steps))
    for step in range(300):
        v, omega = (0.6, 0.3 * np.sin(0.05 * step))
        fast.step(v, omega)
        heading = body.angle + omega * lead_s
        control.velocity = (v * np.cos(heading), v * np.sin(heading))
        control.angular_velocity = omega
        space.step(substep_s)
        (x, y), (vx, vy), theta = body.position, body.velocity, body.angle
        expected = (x, y, theta, vx * np.cos(theta) + vy * np.sin(theta), body.angular_velocity)
        assert fast.state() == expected, step
    assert fast.steps == 300
    assert contacts and max(contacts) == 299  # pressed against the wall to the end


def test_kidnap_moves_the_robot_without_odometry():
    profile = ScriptedProfile([0.0], [0.2], [0.1])
    log = run(profile, (2.0, 2.0, 0.0), 6.0, kidnaps=(KidnapEvent(3.0, (7.0, 6.0, 2.0)),))
    np.testing.assert_array_equal(log.kidnap_t_s, [3.0])
    index = 300
    np.testing.assert_allclose(log.pose[index], (7.0, 6.0, 2.0))
    assert np.hypot(*(log.pose[index, :2] - log.pose[index - 1, :2])) > 4.0
    # the ticks at the jump are those of normal driving
    normal = np.abs(log.wheel_ticks[index - 5 : index]).max()
    assert np.abs(log.wheel_ticks[index]).max() <= normal + 1
    # and the robot keeps driving from the new pose
    assert np.hypot(*(log.pose[-1, :2] - log.pose[index, :2])) > 0.4


@pytest.mark.parametrize(
    ("pose", "words"),
    [
        ((0.1, 4.0, 0.0), "overlaps wall"),
        ((-3.0, 4.0, 0.0), "outside"),
        ((1.0, np.nan, 0.0), "finite"),
    ],
)
def test_bad_start_poses_are_refused(pose, words):
    with pytest.raises(RobotsimError, match=words):
        World(builtin_map("hall"), ROBOT, pose)


def test_bad_world_settings_are_refused():
    with pytest.raises(RobotsimError, match="substeps"):
        WorldParams(substeps=0)
