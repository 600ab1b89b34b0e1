"""Things in the world that the map lacks: unmapped furniture, a person walking.

An :class:`Obstacle` is a polygon or a segment, in world coordinates at ``t = 0``; it stands
still, or it translates (without turning) along a waypoint path at a constant speed. The
path starts at the obstacle's reference point (its centroid: the mean of a segment's end
points, the area centroid of a polygon), visits ``path_m`` in order and, when ``loop``,
comes back to the start and goes round again; otherwise it stops at the last waypoint.

The simulator puts them in the pymunk world (static shapes, or a kinematic body each for
the moving ones: ``robotsim.world``) and in the sonar model (their edges are segments of
the true world at the scan's time: :meth:`Obstacles.cone_distances`). The estimator is never
told of them: its map is the scenario's map alone.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np
import shapely

from robotsim.errors import RobotsimError
from robotsim.sensors.sonar import cone_distances
from validated_records import bounded, validate_fields

#: Shortest edge and smallest polygon area, m and m^2: below, the shape is degenerate.
MIN_EDGE_M = 1e-6
MIN_AREA_M2 = 1e-6


@dataclass(frozen=True, eq=False)
class Obstacle:
    """One unmapped obstacle (module docstring).

    Attributes:
        vertices_m: ``(p, 2)`` a polygon's vertices (p >= 3, in order, not repeated at the
            end, simple: no edge crosses another), or ``(2, 2)`` a segment's end points,
            world frame at ``t = 0``, m.
        polygon: True for a polygon, False for a segment.
        path_m: ``(w, 2)`` the waypoints its reference point visits after its start, m;
            ``(0, 2)``: it stands still.
        speed_m_s: its speed along the path.
        loop: after the last waypoint, back to the start, for ever.
    """

    vertices_m: np.ndarray
    polygon: bool = True
    path_m: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    speed_m_s: float = bounded(1.0, above=0.0, maximum=10.0)
    loop: bool = False

    def __post_init__(self) -> None:
        vertices = np.array(self.vertices_m, dtype=np.float64)
        path = np.array(self.path_m, dtype=np.float64).reshape(-1, 2)
        for name, array in (("vertices_m", vertices), ("path_m", path)):
            if not np.isfinite(array).all():
                raise RobotsimError(f"obstacle {name} must be finite numbers")
            array.setflags(write=False)
            object.__setattr__(self, name, array)
        validate_fields(self, RobotsimError)
        reason = shape_problem(vertices, self.polygon)
        if reason is not None:
            raise RobotsimError(f"obstacle: {reason}")
        if self.loop and len(path) == 0:
            raise RobotsimError("obstacle: a looping obstacle needs a path")
        # per-obstacle constants, built once (the world places a moving one at every step)
        if self.polygon:
            centroid = shapely.Polygon(vertices).centroid
            reference = np.array([centroid.x, centroid.y])
        else:
            reference = vertices.mean(axis=0)
        reference.setflags(write=False)
        object.__setattr__(self, "_reference", reference)
        points = np.vstack([reference, path, *([reference[None]] if self.loop else [])])
        along = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(points, axis=0).T))])
        for array in (points, along):
            array.setflags(write=False)
        object.__setattr__(self, "_points", points)
        object.__setattr__(self, "_along", along)

    @property
    def moving(self) -> bool:
        """True when the obstacle follows a path."""
        return len(self.path_m) > 0

    @property
    def reference_m(self) -> np.ndarray:
        """``(2,)`` the point the path starts at: the centroid (read-only)."""
        return self._reference  # type: ignore[attr-defined]

    def edges_m(self) -> np.ndarray:
        """``(e, 2, 2)`` the edges at ``t = 0`` (a polygon's closed ring, or the segment)."""
        if not self.polygon:
            return self.vertices_m[None].copy()
        return np.stack([self.vertices_m, np.roll(self.vertices_m, -1, axis=0)], axis=1)

    def _path_points(self) -> np.ndarray:
        """``(w + 1, 2)`` (or ``w + 2`` when looping) the path's points, from the start."""
        return self._points  # type: ignore[attr-defined]

    def offset_m(self, t_s) -> np.ndarray:
        """``(..., 2)`` its displacement from where it starts at times ``t_s (...)``."""
        t_s = np.asarray(t_s, dtype=np.float64)
        if not self.moving:
            return np.zeros(t_s.shape + (2,))
        points, along = self._points, self._along  # type: ignore[attr-defined]
        length = along[-1]
        travelled = self.speed_m_s * t_s
        if length == 0.0:
            travelled = np.zeros_like(travelled)
        elif self.loop:
            travelled = np.mod(travelled, length)
        else:
            travelled = np.minimum(travelled, length)
        position = np.stack(
            [np.interp(travelled, along, points[:, 0]), np.interp(travelled, along, points[:, 1])],
            axis=-1,
        )
        return position - points[0]

    def geometry(self, t_s: float = 0.0) -> shapely.Geometry:
        """Its shape at ``t_s`` (a shapely polygon or line string)."""
        vertices = self.vertices_m + self.offset_m(t_s)
        return shapely.Polygon(vertices) if self.polygon else shapely.LineString(vertices)

    def swept(self) -> shapely.Geometry:
        """Every point it covers during the run: its shape at the start and each edge swept
        along each leg of the path (a point the moving shape covers was covered at the start
        or crossed by an edge since)."""
        if not self.moving:
            return self.geometry()
        points = self._path_points()
        shifts = points - points[0]
        edges = self.edges_m()
        pieces = [self.geometry()]
        for a, b in itertools.pairwise(shifts):
            corners = np.concatenate([edges + a, edges + b], axis=1)  # (e, 4, 2)
            pieces.extend(shapely.convex_hull(shapely.multipoints(corners)))
        return shapely.union_all(pieces)


def shape_problem(vertices: np.ndarray, polygon: bool) -> str | None:
    """Why ``vertices`` is not a valid obstacle shape (a simple polygon of non-zero area, or
    a segment of non-zero length), or None."""
    if polygon:
        if vertices.ndim != 2 or vertices.shape[1] != 2 or len(vertices) < 3:
            return f"a polygon needs at least 3 vertices [x, y], got shape {vertices.shape}"
        edges = np.hypot(*(np.roll(vertices, -1, axis=0) - vertices).T)
        if edges.min() < MIN_EDGE_M:
            return f"polygon edge {int(np.argmin(edges))} is degenerate (two equal vertices)"
        shape = shapely.Polygon(vertices)
        if not shape.is_valid:
            return f"the polygon is not simple: {shapely.is_valid_reason(shape)}"
        if shape.area < MIN_AREA_M2:
            return f"the polygon is degenerate (area {shape.area:.3g} m^2)"
        return None
    if vertices.shape != (2, 2):
        return f"a segment needs 2 points [x, y], got shape {vertices.shape}"
    if np.hypot(*(vertices[1] - vertices[0])) < MIN_EDGE_M:
        return "the segment has zero length"
    return None


@dataclass(frozen=True, eq=False)
class Obstacles:
    """The unmapped obstacles of one world (possibly none)."""

    items: tuple[Obstacle, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "items", tuple(self.items))
        static = [o.edges_m() for o in self.items if not o.moving]
        object.__setattr__(
            self, "_static_edges", np.concatenate(static) if static else np.zeros((0, 2, 2))
        )

    def __bool__(self) -> bool:
        return bool(self.items)

    @property
    def static_edges_m(self) -> np.ndarray:
        """``(s, 2, 2)`` the edges of the obstacles that stand still."""
        return self._static_edges  # type: ignore[attr-defined]

    @property
    def moving(self) -> tuple[Obstacle, ...]:
        return tuple(o for o in self.items if o.moving)

    def moving_edges_m(self, t_s) -> np.ndarray:
        """``(n, e, 2, 2)`` the edges of the moving obstacles at each time ``t_s (n,)``."""
        t_s = np.asarray(t_s, dtype=np.float64).reshape(-1)
        parts = [o.edges_m()[None] + o.offset_m(t_s)[:, None, None, :] for o in self.moving]
        return np.concatenate(parts, axis=1) if parts else np.zeros((len(t_s), 0, 2, 2))

    def cone_distances(
        self, poses, t_s, segments, mount_xy, mount_angle_rad, half_aperture_rad: float
    ) -> np.ndarray:
        """``(n, k)`` exact cone distances (``robotsim.sensors.sonar.cone_distances``) from
        the robot at ``poses (n, 3)`` at times ``t_s (n,)`` to the map's ``segments`` and
        the obstacles as they are then (a row depends on its own pose and time only)."""
        poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
        walls = np.concatenate([np.asarray(segments, dtype=np.float64), self.static_edges_m])
        out = cone_distances(poses, walls, mount_xy, mount_angle_rad, half_aperture_rad)
        if self.moving:
            moving = self.moving_edges_m(t_s)
            out = np.minimum(
                out, cone_distances(poses, moving, mount_xy, mount_angle_rad, half_aperture_rad)
            )
        return out

    def clearance_m(self, xy_m, t_s: float) -> float:
        """Distance from the point ``xy_m (2,)`` to the nearest obstacle at ``t_s`` (0 inside
        a polygon; inf without obstacles)."""
        point = shapely.Point(float(xy_m[0]), float(xy_m[1]))
        distances = [shapely.distance(point, o.geometry(t_s)) for o in self.items]
        return float(min(distances, default=np.inf))


#: A world without unmapped obstacles.
NO_OBSTACLES = Obstacles()
