"""The built-in scenarios and their floor plans: they load, their maps are the plans they
claim to be, their start poses and routes lie in free space clear of the walls, the sonar
reaches a wall along most of each route, and a short run on the small plans keeps the truth
in every interval set."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import shapely

from robotsim.control import Route
from robotsim.maps import point_segment_distance
from robotsim.world import WorldParams
from scenarios.builtin import make_plans
from scenarios.runner import run_scenario
from scenarios.spec import builtin_names, load_scenario

#: Clearance asked of the start and of every point of the route polyline beyond the robot's
#: footprint and the walls' collision radius, m (pure pursuit cuts corners by less).
MARGIN_M = 0.1

#: Spacing of the points checked along a route, m.
STEP_M = 0.05

#: What each floor plan is declared to be (issue 13 and the scenario descriptions):
#: bounds ``[[xmin, xmax], [ymin, ymax]]`` m and the least number of segments.
DECLARED = {
    "office_floor": ([[0, 50], [0, 40]], 300),
    "corridor": ([[0, 30], [-0.1, 1.9]], 4),  # 1.8 m wide, closed doors 0.1 m deep niches
    "apartment": ([[0, 12], [0, 9]], 6),
    "cluttered_room": ([[0, 6], [0, 5]], 4 + 4 * 6),  # walls and at least six pieces
    "big_hall": ([[0, 60], [0, 60]], 4),
}

#: Plans large by nature, where the sonar may see no wall along much of the route.
OPEN_PLANS = ("big_hall",)

#: Plans small enough for a short run of the whole pipeline in a test (under a second each).
SMALL_PLANS = ("apartment", "cluttered_room", "hall", "office", "symmetric")


def route_polyline(spec) -> np.ndarray:
    """Points ``(n, 2)`` every :data:`STEP_M` along start -> waypoints (-> first waypoint)."""
    plan = spec.plan
    corners = [np.array(spec.start_pose[:2]), *np.asarray(plan.waypoints_m)]
    if plan.loop:
        corners.append(np.asarray(plan.waypoints_m)[0])
    pieces = []
    for a, b in itertools.pairwise(corners):
        count = max(2, int(np.ceil(np.hypot(*(b - a)) / STEP_M)) + 1)
        pieces.append(a + np.linspace(0.0, 1.0, count)[:, None] * (b - a))
    return np.concatenate(pieces)


def free_face(segments: np.ndarray) -> shapely.Polygon:
    """The largest face the walls close, furniture and pillars cut out as holes: the floor
    the robot drives on (every room of the built-in plans has a door, so it is one face)."""
    lines = shapely.union_all(shapely.linestrings(segments))
    faces = shapely.get_parts(shapely.polygonize(shapely.get_parts(lines)))
    largest = max(faces, key=lambda face: face.area)
    # the faces inside it (furniture) as holes
    holes = [face for face in faces if face is not largest and largest.contains(face)]
    return shapely.difference(largest, shapely.union_all(holes)) if holes else largest


def wall_distance_m(points: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """Distance ``(n,)`` from each point to the nearest segment."""
    return point_segment_distance(points[:, None, :], segments[:, 0], segments[:, 1]).min(axis=1)


@pytest.mark.parametrize("name", builtin_names())
def test_every_builtin_scenario_loads_with_a_closed_outer_wall_and_a_route(name):
    spec = load_scenario(name)
    # named after its map: hall_mcl is the hall localised by the particle filter; a plan with
    # unmapped obstacles is the plan of its name's first word, lived in
    plan = name.split("_")[0] if spec.obstacles else name.split("_mcl")[0]
    assert spec.name == name and spec.map.name == plan
    assert spec.map.boundary is not None
    assert isinstance(spec.plan, Route) and len(spec.plan.waypoints_m) >= 2


@pytest.mark.parametrize("name", builtin_names())
def test_start_and_route_lie_in_free_space_clear_of_every_wall(name):
    spec = load_scenario(name)
    segments = spec.map.segments
    clearance = spec.robot.radius_m + WorldParams().wall_radius_m + MARGIN_M
    floor = free_face(segments)
    points = route_polyline(spec)
    # the start, every waypoint and every point between: on the floor, not in furniture
    assert shapely.contains_xy(floor, points[:, 0], points[:, 1]).all()
    distance = wall_distance_m(points, segments)
    worst = int(np.argmin(distance))
    assert distance[worst] >= clearance, f"{name}: {points[worst]} is {distance[worst]:.3f} m off"
    # and of every unmapped obstacle, wherever a moving one goes (the robot does not swerve)
    for obstacle in spec.obstacles.items:
        gap = shapely.distance(obstacle.swept(), shapely.points(points))
        assert gap.min() >= clearance, f"{name}: the route passes {gap.min():.3f} m off an obstacle"


@pytest.mark.parametrize("name", sorted(set(builtin_names()) - set(OPEN_PLANS)))
def test_the_sonar_reaches_a_wall_along_most_of_the_route(name):
    spec = load_scenario(name)
    sonar = spec.sensors.sonar
    points = route_polyline(spec)
    # a wall within reach of the belt (sensors on the rim, range d_max)
    in_reach = wall_distance_m(points, spec.map.segments) <= sonar.d_max_m + spec.robot.radius_m
    assert in_reach.mean() >= 0.95


def test_the_open_hall_has_stretches_beyond_the_sonar_and_stretches_along_walls():
    spec = load_scenario("big_hall")
    points = route_polyline(spec)
    distance = wall_distance_m(points, spec.map.segments)
    reach = spec.sensors.sonar.d_max_m
    assert 0.2 < (distance > reach + spec.robot.radius_m).mean() < 0.8
    assert (distance < reach).mean() > 0.5


@pytest.mark.parametrize("name", sorted(DECLARED))
def test_each_plan_has_its_declared_size_and_segment_count(name):
    bounds, least_segments = DECLARED[name]
    segment_map = load_scenario(name).map
    np.testing.assert_allclose(segment_map.bounds, bounds, atol=1e-9)
    assert len(segment_map.segments) >= least_segments
    # the map file is the one the generator draws (python -m scenarios.builtin.make_plans)
    plan = make_plans.PLANS[name]()
    assert make_plans.map_path(name).read_text(encoding="utf-8") == plan.wkt()
    assert len(segment_map.segments) == plan.segment_count()


def test_the_office_floor_has_rooms_along_corridors_with_doors():
    plan = make_plans.office_floor()
    rooms = sum(row.rooms for row in make_plans.OFFICE_ROWS.values())
    assert rooms == 38
    # one door gap per room: the door walls are cut into rooms + 1 pieces per row
    door_wall_pieces = (
        len(plan.walls) - 7 - sum(r.rooms - 1 for r in make_plans.OFFICE_ROWS.values())
    )
    assert door_wall_pieces == rooms + len(make_plans.OFFICE_ROWS)
    # every room's door is a 1 m gap: its centre is at least half a door from every wall
    segments = load_scenario("office_floor").map.segments
    centres = np.array(
        [row.door_centre(i) for row in make_plans.OFFICE_ROWS.values() for i in range(row.rooms)]
    )
    np.testing.assert_allclose(
        wall_distance_m(centres, segments), make_plans.OFFICE_DOOR_M / 2.0, atol=1e-9
    )


def test_the_corridor_is_1_8_m_wide_between_its_long_walls():
    segments = load_scenario("corridor").map.segments
    horizontal = segments[segments[:, 0, 1] == segments[:, 1, 1]]
    lengths = np.abs(horizontal[:, 1, 0] - horizontal[:, 0, 0])
    # the wall pieces between the niches, by their y, cover most of the 30 m on each side
    for y in (0.0, 1.8):
        assert lengths[horizontal[:, 0, 1] == y].sum() > 0.8 * 30.0


@pytest.mark.parametrize("name", SMALL_PLANS)
def test_a_short_run_on_a_small_plan_keeps_the_truth_in_every_set(name):
    spec = load_scenario(name).with_run(duration_s=5.0)
    result = run_scenario(spec)
    summary = result.summary
    assert summary["epochs"] == len(result.log.sonar_t_s) >= 5 and summary["empty_epochs"] == 0
    assert summary["containment"] == 1.0
    # containment by brute force: the true pose at each scan in some box of its epoch
    epochs = result.estimation.epochs
    for e, pose in enumerate(result.log.sonar_pose):
        boxes = epochs.epoch_boxes(e)
        assert np.all((boxes[:, :, 0] <= pose) & (pose <= boxes[:, :, 1]), axis=1).any()
