"""Geometric feasibility (issue 12, items 6 and 7): impossible scenarios refused by file, key
and reason, before anything runs; the built-in scenarios all pass."""

from __future__ import annotations

import numpy as np
import pytest
import shapely

from robotsim.maps import SegmentMap, builtin_map, polygon_segments
from scenarios.errors import ScenarioError
from scenarios.feasibility import solid_obstacles
from scenarios.spec import builtin_names, load_scenario, parse_scenario

HALL_WITH_PILLAR = """
[map]
segments = [[[0, 0], [10, 0]], [[10, 0], [10, 8]], [[10, 8], [0, 8]], [[0, 8], [0, 0]],
            [[4, 4], [6, 4]], [[6, 4], [6, 6]], [[6, 6], [4, 6]], [[4, 6], [4, 4]]]
"""


def refusal(text: str, tmp_path=None, **files: str) -> ScenarioError:
    base = None
    if files:
        for name, content in files.items():
            (tmp_path / name.replace("_", ".")).write_text(content)
        base = tmp_path
    with pytest.raises(ScenarioError) as caught:
        parse_scenario(text, source="s.toml", base_dir=base)
    assert caught.value.source == "s.toml"
    return caught.value


def test_a_start_inside_a_solid_pillar_is_refused():
    error = refusal(HALL_WITH_PILLAR + "[robot]\nstart_xy_m = [5.0, 5.0]\n")
    assert error.key == "robot.start_xy_m" and "inside a solid obstacle" in error.reason


def test_a_start_inside_a_wkt_polygons_hole_is_refused(tmp_path):
    wkt = "POLYGON ((0 0, 10 0, 10 8, 0 8, 0 0), (3 3, 7 3, 7 6, 3 6, 3 3))\n"
    text = '[map]\nfile = "room.wkt"\n[robot]\nstart_xy_m = [5.0, 4.5]\n'
    error = refusal(text, tmp_path, room_wkt=wkt)
    assert error.key == "robot.start_xy_m" and "inside a solid obstacle" in error.reason
    # the same room with the start in its free part is accepted
    parse_scenario(text.replace("[5.0, 4.5]", "[1.0, 1.0]"), source="s.toml", base_dir=tmp_path)


@pytest.mark.parametrize(
    ("waypoint", "reason"),
    [("[5.0, 5.0]", "inside a solid obstacle"), ("[3.9, 5.0]", "closer than the robot's radius")],
)
def test_a_waypoint_in_an_obstacle_or_against_a_wall_is_refused(waypoint, reason):
    text = HALL_WITH_PILLAR + (
        f"[robot]\nstart_xy_m = [1.0, 1.0]\n[route]\nwaypoints_m = [[2.0, 2.0], [2.0, 7.0], {waypoint}]\n"
    )
    error = refusal(text)
    assert error.key == "route.waypoints_m[2]" and reason in error.reason


def test_a_sonar_mounted_off_the_body_is_refused_against_its_mount():
    """Before: the run went on and failed with SIVIA's "raise eps or shrink the initial box"."""
    text = (
        "[robot]\nstart_xy_m = [5.0, 4.0]\n[sensors.sonar]\n"
        "mount_xy = [[0.2, 0.0], [0.0, 0.2], [-5.2, 0.0], [0.0, -0.2]]\n"
        "mount_angle_rad = [0.0, 1.57, 3.14, -1.57]\n"
    )
    error = refusal(text)
    assert error.key == "sensors.sonar.mount_xy[2]" and "off its body" in error.reason
    assert "5.2 m from the robot's centre" in error.reason


def test_a_map_of_one_segment_is_blamed_on_the_map():
    """Before: ``estimation: map bounds must be a finite (2, 2) box``."""
    error = refusal(
        "[map]\nsegments = [[[0.0, 0.0], [5.0, 0.0]]]\n[robot]\nstart_xy_m = [1.0, 1.0]\n"
    )
    assert error.key == "map" and "span no area" in error.reason


def test_solid_obstacles_are_the_closed_regions_off_the_outer_wall():
    hall = builtin_map("hall")
    pillar = shapely.box(2.3, 1.8, 2.7, 2.2)  # hall's square pillar; its other landmarks are open
    assert solid_obstacles(hall).equals(pillar)
    # a room closed by walls that meet the outer wall is free space, not an obstacle
    outer = np.array([[0.0, 0.0], [8.0, 0.0], [8.0, 6.0], [0.0, 6.0]])
    divided = SegmentMap.from_segments(
        np.concatenate([polygon_segments(outer), [[[4.0, 0.0], [4.0, 6.0]]]]), boundary=outer
    )
    assert solid_obstacles(divided).is_empty


@pytest.mark.parametrize("name", builtin_names())
def test_every_builtin_scenario_is_feasible(name):
    load_scenario(name)
