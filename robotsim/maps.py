"""Segment maps: the walls and landmarks of the world, their loaders and a box query.

A map is an array ``segments`` of shape ``(m, 2, 2)`` (float64, metres, world frame):
``segments[j, 0] = (ax, ay)`` and ``segments[j, 1] = (bx, by)``. The same array feeds the
pymunk world (static wall shapes), the exact sonar cone model and the interval inclusion
tests, so it is validated once here: at least one segment, finite coordinates, no
zero-length segment.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import shapely
import shapely.errors
from shapely.geometry.base import BaseGeometry

from robotsim.errors import MapError

#: Segments shorter than this (metres) count as zero-length.
MIN_SEGMENT_LENGTH_M = 1e-9


def _as_segments(segments: Any, name: str) -> np.ndarray:
    """Validate and return a read-only float64 copy of a segment array ``(m, 2, 2)``."""
    try:
        array = np.array(segments, dtype=np.float64)
    except (TypeError, ValueError) as error:
        raise MapError(f"map {name!r}: segments are not numbers: {error}") from None
    if array.size == 0:
        raise MapError(f"map {name!r}: the map has no segments (at least one is needed)")
    if array.ndim != 3 or array.shape[1:] != (2, 2):
        raise MapError(
            f"map {name!r}: segments must have shape (m, 2, 2) = [[ax, ay], [bx, by]] per "
            f"segment, got shape {array.shape}"
        )
    bad = ~np.isfinite(array).all(axis=(1, 2))
    if bad.any():
        index = int(np.flatnonzero(bad)[0])
        raise MapError(
            f"map {name!r}: segment {index} has a non-finite coordinate {array[index].tolist()}"
        )
    length_m = np.hypot(*(array[:, 1] - array[:, 0]).T)
    short = length_m < MIN_SEGMENT_LENGTH_M
    if short.any():
        index = int(np.flatnonzero(short)[0])
        raise MapError(
            f"map {name!r}: segment {index} has zero length (both ends at "
            f"{array[index, 0].tolist()})"
        )
    array.setflags(write=False)
    return array


def _as_boundary(boundary: Any, name: str) -> np.ndarray | None:
    """Validate the outer wall polygon ``(p, 2)`` (p >= 3 distinct vertices, not repeated)."""
    if boundary is None:
        return None
    try:
        array = np.array(boundary, dtype=np.float64)
    except (TypeError, ValueError) as error:
        raise MapError(f"map {name!r}: boundary is not numbers: {error}") from None
    if array.ndim != 2 or array.shape[1] != 2:
        raise MapError(f"map {name!r}: boundary must have shape (p, 2), got {array.shape}")
    if len(array) > 1 and np.array_equal(array[0], array[-1]):
        array = array[:-1]
    if len(array) < 3:
        raise MapError(f"map {name!r}: boundary needs at least 3 vertices, got {len(array)}")
    if not np.isfinite(array).all():
        raise MapError(f"map {name!r}: boundary has a non-finite coordinate")
    array.setflags(write=False)
    return array


def polygon_segments(vertices_m: Any) -> np.ndarray:
    """Segments ``(p, 2, 2)`` of the closed polygon through ``vertices_m`` ``(p, 2)``."""
    vertices = np.asarray(vertices_m, dtype=np.float64)
    return np.stack([vertices, np.roll(vertices, -1, axis=0)], axis=1)


def polyline_segments(points_m: Any) -> np.ndarray:
    """Segments ``(p - 1, 2, 2)`` of the open polyline through ``points_m`` ``(p, 2)``."""
    points = np.asarray(points_m, dtype=np.float64)
    return np.stack([points[:-1], points[1:]], axis=1)


def _geometry_segments(geometry: BaseGeometry) -> list[np.ndarray]:
    """Segment arrays of every line, ring or polygon edge in a shapely geometry."""
    if geometry.is_empty:
        return []
    kind = geometry.geom_type
    if kind in ("LineString", "LinearRing"):
        coords = np.asarray(geometry.coords, dtype=np.float64)[:, :2]
        return [polyline_segments(coords)] if len(coords) >= 2 else []
    if kind == "Polygon":
        return [
            piece
            for ring in (geometry.exterior, *geometry.interiors)
            for piece in _geometry_segments(ring)
        ]
    if kind in ("MultiLineString", "MultiPolygon", "GeometryCollection"):
        return [piece for part in geometry.geoms for piece in _geometry_segments(part)]
    raise MapError(f"geometry type {kind} cannot be a wall (use LineString or Polygon)")


def _parse(reader: Callable[[str], BaseGeometry], text: str, kind: str, name: str) -> BaseGeometry:
    """``reader(text)``, any parse failure raised as a :class:`MapError` naming ``kind``."""
    try:
        return reader(text)
    except (shapely.errors.ShapelyError, TypeError, ValueError) as error:
        raise MapError(f"map {name!r}: unreadable {kind}: {error}") from None


def _outer_polygon(geometry: BaseGeometry) -> np.ndarray | None:
    """Exterior ring ``(p, 2)`` of the largest polygon in a geometry, if there is one."""
    polygons = [
        part
        for part in getattr(geometry, "geoms", [geometry])
        if part.geom_type == "Polygon" and not part.is_empty
    ]
    if not polygons:
        return None
    largest = max(polygons, key=lambda polygon: polygon.area)
    return np.asarray(largest.exterior.coords, dtype=np.float64)[:-1, :2]


def outer_wall(segments: np.ndarray) -> np.ndarray | None:
    """The outer wall ``(p, 2)`` closed by segments ``(m, 2, 2)``: the largest polygon they
    close, if it encloses every segment; otherwise None (the map has no outer wall).

    For maps given as loose segments or line strings (inline segments, WKT line strings,
    GeoJSON LineStrings): the same room gets the same boundary whatever its format.
    """
    lines = shapely.union_all(shapely.linestrings(segments))
    polygons = shapely.get_parts(shapely.polygonize(shapely.get_parts(lines)))
    if len(polygons) == 0:
        return None
    largest = max(polygons, key=lambda polygon: polygon.area)
    if not shapely.contains_xy(largest.buffer(1e-9), segments[..., 0], segments[..., 1]).all():
        return None
    return np.asarray(largest.exterior.coords, dtype=np.float64)[:-1, :2]


@dataclass(frozen=True, eq=False)
class SegmentMap:
    """A validated segment map.

    Attributes:
        segments: ``(m, 2, 2)`` float64 metres, world frame, read-only;
            ``segments[j] = [[ax, ay], [bx, by]]``.
        name: a label for messages and recordings.
        boundary: the outer wall polygon ``(p, 2)`` metres (vertices in order, first not
            repeated) whose interior is the free space, or ``None`` when the map has no
            closed outer wall.
    """

    segments: np.ndarray
    name: str = "map"
    boundary: np.ndarray | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "segments", _as_segments(self.segments, self.name))
        object.__setattr__(self, "boundary", _as_boundary(self.boundary, self.name))

    @classmethod
    def from_segments(cls, segments: Any, name: str = "map", boundary: Any = None) -> SegmentMap:
        """A map from a nested list or array of segments ``[[[ax, ay], [bx, by]], ...]``."""
        return cls(segments=segments, name=name, boundary=boundary)

    @classmethod
    def _from_geometry(cls, geometry: BaseGeometry, name: str, boundary: Any) -> SegmentMap:
        pieces = _geometry_segments(geometry)
        if not pieces:
            raise MapError(f"map {name!r}: the geometry holds no line segments")
        segments = np.concatenate(pieces, axis=0)
        if boundary is None:
            boundary = _outer_polygon(geometry)
        if boundary is None:  # line strings only: the polygon they close, as for inline segments
            boundary = outer_wall(_as_segments(segments, name))
        return cls(segments=segments, name=name, boundary=boundary)

    @classmethod
    def from_wkt(cls, text: str, name: str = "map", boundary: Any = None) -> SegmentMap:
        """A map from WKT (LineString, MultiLineString, Polygon, GeometryCollection, ...).

        Every consecutive pair of vertices becomes a segment; a polygon's rings become walls
        and the exterior of the largest polygon becomes ``boundary`` unless one is given.
        Without a polygon, the boundary is the :func:`outer_wall` the line strings close.
        """
        return cls._from_geometry(_parse(shapely.from_wkt, text, "WKT", name), name, boundary)

    @classmethod
    def from_geojson(cls, data: str | dict, name: str = "map", boundary: Any = None) -> SegmentMap:
        """A map from GeoJSON text or a parsed dict (Geometry, Feature or FeatureCollection).

        Same rules as :meth:`from_wkt`; coordinates are read as metres.
        """
        text = json.dumps(data) if isinstance(data, dict) else data
        geometry = _parse(shapely.from_geojson, text, "GeoJSON", name)
        return cls._from_geometry(geometry, name, boundary)

    @property
    def bounds(self) -> np.ndarray:
        """Bounding box ``(2, 2)`` = ``[[xmin, xmax], [ymin, ymax]]`` metres of all walls."""
        points = self.segments.reshape(-1, 2)
        if self.boundary is not None:
            points = np.concatenate([points, self.boundary], axis=0)
        return np.stack([points.min(axis=0), points.max(axis=0)], axis=1)

    def segments_near_box(self, box: Any, distance_m: float) -> np.ndarray:
        """Segments ``(m', 2, 2)`` whose Euclidean distance to an x-y box is <= distance_m.

        Args:
            box: ``(2, 2)`` or ``(3, 2)`` box (rows x, y[, theta]; columns lower, upper);
                only the x and y rows are used.
            distance_m: non-negative distance.

        The distance between a segment and a rectangle is zero when they intersect
        (Liang-Barsky clipping), otherwise the minimum of the distances from the segment's
        end points to the rectangle and from the rectangle's corners to the segment (two
        disjoint convex sets are closest at a vertex of one of them). Vectorised over the
        segments; a relative slack of 1e-9 keeps borderline segments in (never drops one).
        """
        box_array = np.asarray(box, dtype=np.float64)
        if box_array.ndim != 2 or box_array.shape[0] < 2 or box_array.shape[1] != 2:
            raise MapError(f"box must have shape (2, 2) or (3, 2), got {box_array.shape}")
        if not np.isfinite(distance_m) or distance_m < 0:
            raise MapError(f"distance_m must be finite and >= 0, got {distance_m}")
        lower, upper = box_array[:2, 0], box_array[:2, 1]
        a, b = self.segments[:, 0], self.segments[:, 1]
        distance = np.minimum(
            _point_box_distance(a, lower, upper), _point_box_distance(b, lower, upper)
        )
        corners = np.array(
            [[lower[0], lower[1]], [upper[0], lower[1]], [upper[0], upper[1]], [lower[0], upper[1]]]
        )
        corner_distance = point_segment_distance(corners[:, None, :], a, b).min(axis=0)
        distance = np.minimum(distance, corner_distance)
        distance[_segment_hits_box(a, b, lower, upper)] = 0.0
        slack = 1e-9 * (1.0 + np.abs(box_array[:2]).max() + distance_m)
        return self.segments[distance <= distance_m + slack]


def _point_box_distance(points: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """Distance ``(n,)`` from points ``(n, 2)`` to the rectangle ``[lower, upper]``."""
    gap = np.maximum(np.maximum(lower - points, points - upper), 0.0)
    return np.hypot(gap[:, 0], gap[:, 1])


def point_segment_distance(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance from points ``(..., 2)`` to segments ``[a, b]`` (``(..., 2)``, broadcast)."""
    edge = b - a
    t = np.einsum("...i,...i->...", points - a, edge) / np.einsum("...i,...i->...", edge, edge)
    foot = a + np.clip(t, 0.0, 1.0)[..., None] * edge
    return np.linalg.norm(points - foot, axis=-1)


#: Points per block of :func:`nearest_segment_distance` (consecutive samples of a path).
NEAREST_BLOCK_POINTS = 256


def nearest_segment_distance(points: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """``(N,)`` the distance from each point ``(N, 2)`` to the nearest of ``segments (m, 2, 2)``:
    ``min_j point_segment_distance(p, a_j, b_j)``, the same value bit for bit, at the cost of
    the segments near each block of points only.

    Points are taken in blocks of :data:`NEAREST_BLOCK_POINTS` consecutive rows (a path's
    samples, so a block spans a small box). For a block of bounding box ``B`` with centre
    ``c`` and half-diagonal ``h``, every point ``p`` of it has a segment within
    ``U = min_j d(c, j) + h`` (triangle inequality), so its nearest segment ``j`` has
    ``d(B, box_j) <= d(p, j) <= U``: the segments whose bounding box lies farther than ``U``
    from ``B`` are never the nearest and are skipped (a relative slack of 1e-9 keeps the
    borderline ones). The kept ones go through :func:`point_segment_distance` as a whole
    array would, so the minimum is the one of the whole array. On a 60 s path this costs
    9-14 ms on maps of 12 to 52 segments (29-114 ms whole) and 27 ms on 495 (load 7).
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    segments = np.asarray(segments, dtype=np.float64)
    a, b = segments[:, 0], segments[:, 1]
    if len(points) == 0:
        return np.zeros(0)
    lower, upper = np.minimum(a, b), np.maximum(a, b)  # (m, 2) each segment's box
    out = np.empty(len(points))
    for start in range(0, len(points), NEAREST_BLOCK_POINTS):
        block = points[start : start + NEAREST_BLOCK_POINTS]
        low, high = block.min(axis=0), block.max(axis=0)
        centre, half_diagonal = 0.5 * (low + high), 0.5 * float(np.hypot(*(high - low)))
        reach = point_segment_distance(centre, a, b).min() + half_diagonal
        gap = np.maximum(np.maximum(lower - high, low - upper), 0.0)  # box to box, per axis
        near = np.hypot(gap[:, 0], gap[:, 1]) <= reach * (1.0 + 1e-9) + 1e-12
        out[start : start + len(block)] = point_segment_distance(
            block[:, None, :], a[near], b[near]
        ).min(axis=1)
    return out


def _segment_hits_box(
    a: np.ndarray, b: np.ndarray, lower: np.ndarray, upper: np.ndarray
) -> np.ndarray:
    """Whether segments ``[a, b]`` ``(m, 2)`` meet the closed rectangle (Liang-Barsky)."""
    direction = b - a
    with np.errstate(divide="ignore", invalid="ignore"):
        t_low = (lower - a) / direction
        t_high = (upper - a) / direction
    parallel = direction == 0.0
    t_enter = np.where(parallel, -np.inf, np.minimum(t_low, t_high))
    t_exit = np.where(parallel, np.inf, np.maximum(t_low, t_high))
    outside_slab = parallel & ((a < lower) | (a > upper))
    t_start = np.maximum(t_enter.max(axis=1), 0.0)
    t_end = np.minimum(t_exit.min(axis=1), 1.0)
    return (t_start <= t_end) & ~outside_slab.any(axis=1)


# Built-in maps -------------------------------------------------------------------------


def _rectangle(width_m: float, height_m: float) -> np.ndarray:
    """Corners ``(4, 2)`` of the rectangle ``[0, width] x [0, height]``, counter-clockwise."""
    return np.array([[0.0, 0.0], [width_m, 0.0], [width_m, height_m], [0.0, height_m]])


def _hall() -> SegmentMap:
    """A 10 m x 8 m room with four sparse, dissimilar landmarks >= 3 m apart.

    In the spirit of paper 002, figure 1: few landmarks, so that the 3 m sonar range
    often sees one landmark or a wall only. The landmarks differ in shape and the layout
    has no symmetry, so global localisation can narrow down to one pose.
    """
    outer = _rectangle(10.0, 8.0)
    landmarks = [
        polygon_segments([[2.3, 1.8], [2.7, 1.8], [2.7, 2.2], [2.3, 2.2]]),  # square pillar
        polyline_segments([[6.0, 5.4], [6.0, 6.6]]),  # short straight wall
        polyline_segments([[7.0, 1.5], [8.2, 1.5], [8.2, 2.3]]),  # L-shaped corner piece
        polyline_segments([[1.6, 5.4], [2.4, 6.2]]),  # diagonal wall piece
    ]
    segments = np.concatenate([polygon_segments(outer), *landmarks], axis=0)
    return SegmentMap(segments=segments, name="hall", boundary=outer)


def _office() -> SegmentMap:
    """A 12 m x 8 m floor: an east-west corridor (y 3.5 to 5 m), three rooms south of it,
    two rooms north, each entered by a 0.9 m door at a different offset."""
    outer = _rectangle(12.0, 8.0)
    walls = np.array(
        [
            # south corridor wall with doors at x 1.5-2.4, 5.5-6.4, 9.5-10.4
            [[0.0, 3.5], [1.5, 3.5]],
            [[2.4, 3.5], [5.5, 3.5]],
            [[6.4, 3.5], [9.5, 3.5]],
            [[10.4, 3.5], [12.0, 3.5]],
            # south room dividers
            [[4.0, 0.0], [4.0, 3.5]],
            [[8.0, 0.0], [8.0, 3.5]],
            # north corridor wall with doors at x 2.5-3.4 and 8.5-9.4
            [[0.0, 5.0], [2.5, 5.0]],
            [[3.4, 5.0], [8.5, 5.0]],
            [[9.4, 5.0], [12.0, 5.0]],
            # north room divider
            [[6.0, 5.0], [6.0, 8.0]],
        ]
    )
    segments = np.concatenate([polygon_segments(outer), walls], axis=0)
    return SegmentMap(segments=segments, name="office", boundary=outer)


def _symmetric() -> SegmentMap:
    """A plain 8 m x 6 m rectangle: every pose has a twin turned by pi (ambiguous)."""
    outer = _rectangle(8.0, 6.0)
    return SegmentMap(segments=polygon_segments(outer), name="symmetric", boundary=outer)


_BUILTIN_MAPS = {"hall": _hall, "office": _office, "symmetric": _symmetric}

#: Names accepted by :func:`builtin_map`.
BUILTIN_MAP_NAMES: tuple[str, ...] = tuple(_BUILTIN_MAPS)


def builtin_map(name: str) -> SegmentMap:
    """The built-in map called ``name`` (one of :data:`BUILTIN_MAP_NAMES`)."""
    try:
        factory = _BUILTIN_MAPS[name]
    except KeyError:
        raise MapError(
            f"unknown built-in map {name!r}; choose one of {', '.join(BUILTIN_MAP_NAMES)}"
        ) from None
    return factory()
