"""Geometric feasibility of a scenario: what no simulation of it could make sense of.

The spec loader (``scenarios.spec``) reads and bounds every key; this module then checks
the geometry the keys describe together, each failure a ``ScenarioError`` naming the file,
the key and the reason:

- the map spans an area (walls in two directions): the interval localisation searches the
  map's bounding box, which a straight line of walls reduces to nothing;
- the start pose and every waypoint lie in free space with the robot's footprint: inside
  the outer wall, clear of every wall by ``robot.radius_m``, and not inside a solid
  obstacle;
- every sonar sits on the robot's body (``|mount_xy| <= robot.radius_m``).

A solid obstacle is a region the walls enclose completely that touches the outer wall
nowhere: a closed pillar of segments, a hole (interior ring) of a WKT or GeoJSON polygon.
A region closed off by walls that meet the outer wall (a room without a door) counts as
free space.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import shapely

from robotsim.control import Route
from robotsim.maps import SegmentMap
from scenarios.errors import ScenarioError

if TYPE_CHECKING:
    from scenarios.spec import ScenarioSpec

#: Relative slack on the sonar mount radius: the default belt sits on the rim exactly.
MOUNT_RIM_TOLERANCE = 1e-9


def check_feasible(spec: ScenarioSpec) -> ScenarioSpec:
    """Return ``spec`` unchanged if it is geometrically possible; raise ``ScenarioError``."""
    _check_map_area(spec)
    obstacles = solid_obstacles(spec.map)
    radius_m = spec.robot.radius_m
    x, y, _ = spec.start_pose
    reason = _placement_problem(spec.map, obstacles, np.array([[x, y]]), radius_m)[0]
    if reason:
        raise ScenarioError(spec.source, "robot.start_xy_m", f"({x:g}, {y:g}) {reason}")
    if isinstance(spec.plan, Route):
        points = np.asarray(spec.plan.waypoints_m, dtype=np.float64)
        for i, reason in enumerate(_placement_problem(spec.map, obstacles, points, radius_m)):
            if reason:
                where = f"({points[i, 0]:g}, {points[i, 1]:g})"
                raise ScenarioError(spec.source, f"route.waypoints_m[{i}]", f"{where} {reason}")
    _check_mounts(spec)
    return spec


def _check_map_area(spec: ScenarioSpec) -> None:
    bounds = spec.map.bounds  # (2, 2): rows x, y; columns lower, upper
    extent = bounds[:, 1] - bounds[:, 0]
    if not np.all(extent > 0.0):
        raise ScenarioError(
            spec.source,
            "map",
            f"the walls span no area (extent {extent[0]:g} m x {extent[1]:g} m): "
            "give walls in two directions",
        )


def solid_obstacles(segment_map: SegmentMap) -> shapely.Geometry:
    """The union of the map's solid obstacles (empty when there is none).

    The faces of the wall arrangement (walls cut where they cross) that touch the outer
    wall nowhere; without an outer wall, every enclosed face.
    """
    lines = shapely.linestrings(segment_map.segments)
    faces = shapely.get_parts(shapely.polygonize(shapely.get_parts(shapely.union_all(lines))))
    if segment_map.boundary is not None:
        outer = shapely.LinearRing(segment_map.boundary)
        faces = faces[~shapely.intersects(shapely.get_exterior_ring(faces), outer)]
    return shapely.union_all(faces)


def _placement_problem(
    segment_map: SegmentMap, obstacles: shapely.Geometry, points: np.ndarray, radius_m: float
) -> list[str | None]:
    """Why the robot's footprint (a disk of ``radius_m``) cannot stand at each of
    ``points (P, 2)``, or None where it can."""
    centres = shapely.points(points)
    inside = (
        shapely.contains_xy(shapely.Polygon(segment_map.boundary), points[:, 0], points[:, 1])
        if segment_map.boundary is not None
        else np.ones(len(points), dtype=bool)
    )
    walls = shapely.multilinestrings(segment_map.segments)
    clearance = shapely.distance(centres, walls)
    solid = shapely.contains(obstacles, centres)
    reasons: list[str | None] = []
    for i in range(len(points)):
        if not inside[i]:
            reasons.append("lies outside the map's outer wall")
        elif solid[i]:
            reasons.append("lies inside a solid obstacle of the map (a closed pillar or hole)")
        elif clearance[i] < radius_m:
            reasons.append(
                f"is {clearance[i]:.3g} m from a wall, closer than the robot's radius "
                f"(robot.radius_m = {radius_m:g})"
            )
        else:
            reasons.append(None)
    return reasons


def _check_mounts(spec: ScenarioSpec) -> None:
    mounts = np.asarray(spec.sensors.sonar.mount_xy, dtype=np.float64)
    reach = np.hypot(mounts[:, 0], mounts[:, 1])
    radius_m = spec.robot.radius_m
    outside = np.flatnonzero(reach > radius_m * (1.0 + MOUNT_RIM_TOLERANCE))
    if outside.size:
        i = int(outside[0])
        raise ScenarioError(
            spec.source,
            f"sensors.sonar.mount_xy[{i}]",
            f"({mounts[i, 0]:g}, {mounts[i, 1]:g}) is {reach[i]:.3g} m from the robot's centre, "
            f"off its body (robot.radius_m = {radius_m:g}): a sonar sits on the robot",
        )
