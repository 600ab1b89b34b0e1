"""Segment maps: validation, loaders, the box query, the built-in maps."""

import json
from pathlib import Path

import numpy as np
import pytest
import shapely

from robotsim import maps
from robotsim.errors import MapError
from robotsim.maps import (
    BUILTIN_MAP_NAMES,
    SegmentMap,
    builtin_map,
    nearest_segment_distance,
    outer_wall,
    point_segment_distance,
)

#: The built-in office floor plan (495 segments), a map file of the scenarios.
OFFICE_FLOOR_WKT = Path(__file__).parents[2] / "scenarios" / "builtin" / "maps" / "office_floor.wkt"


@pytest.mark.parametrize(
    ("segments", "words"),
    [
        ([], "no segments"),
        (np.zeros((0, 2, 2)), "no segments"),
        ([[[0.0, 0.0], [np.nan, 1.0]]], "non-finite"),
        ([[[0.0, 0.0], [1.0, 1.0]], [[2.0, np.inf], [1.0, 1.0]]], "segment 1"),
        ([[[1.0, 2.0], [1.0, 2.0]]], "zero length"),
        ([[0.0, 0.0, 1.0, 1.0]], "shape"),
        ([[["a", 0.0], [1.0, 1.0]]], "not numbers"),
    ],
)
def test_invalid_segments_are_refused_with_a_message_naming_the_reason(segments, words):
    with pytest.raises(MapError, match=words):
        SegmentMap.from_segments(segments, name="bad")


def test_segments_are_read_only_float64():
    the_map = SegmentMap.from_segments([[[0, 0], [1, 0]]])
    assert the_map.segments.dtype == np.float64
    with pytest.raises(ValueError):
        the_map.segments[0, 0, 0] = 5.0


def test_wkt_line_strings_become_consecutive_segments():
    the_map = SegmentMap.from_wkt("MULTILINESTRING ((0 0, 2 0, 2 1), (5 5, 6 6))")
    expected = [[[0, 0], [2, 0]], [[2, 0], [2, 1]], [[5, 5], [6, 6]]]
    np.testing.assert_array_equal(the_map.segments, expected)
    assert the_map.boundary is None


def test_wkt_polygon_gives_walls_and_boundary():
    the_map = SegmentMap.from_wkt("POLYGON ((0 0, 4 0, 4 3, 0 3, 0 0))", name="room")
    assert the_map.segments.shape == (4, 2, 2)
    np.testing.assert_array_equal(the_map.boundary, [[0, 0], [4, 0], [4, 3], [0, 3]])
    np.testing.assert_array_equal(the_map.bounds, [[0, 4], [0, 3]])


def test_geojson_feature_collection_matches_wkt():
    geojson = {
        "type": "FeatureCollection",
        "features": [
            {
                "type": "Feature",
                "properties": {},
                "geometry": {"type": "LineString", "coordinates": [[0, 0], [3, 0], [3, 2]]},
            },
            {
                "type": "Feature",
                "properties": {},
                "geometry": {"type": "LineString", "coordinates": [[1, 1], [1, 2]]},
            },
        ],
    }
    from_dict = SegmentMap.from_geojson(geojson)
    from_text = SegmentMap.from_geojson(json.dumps(geojson))
    from_wkt = SegmentMap.from_wkt("MULTILINESTRING ((0 0, 3 0, 3 2), (1 1, 1 2))")
    np.testing.assert_array_equal(from_dict.segments, from_wkt.segments)
    np.testing.assert_array_equal(from_text.segments, from_wkt.segments)


@pytest.mark.parametrize(
    ("loader", "text", "words"),
    [
        (SegmentMap.from_wkt, "LINESTRING (0 0", "unreadable WKT"),
        (SegmentMap.from_wkt, "POINT (1 1)", "cannot be a wall"),
        (SegmentMap.from_wkt, "LINESTRING EMPTY", "no line segments"),
        (SegmentMap.from_wkt, "LINESTRING (0 0, 0 0)", "zero length"),
        (SegmentMap.from_geojson, '{"type": "LineString"', "unreadable GeoJSON"),
    ],
)
def test_bad_wkt_and_geojson_are_refused(loader, text, words):
    with pytest.raises(MapError, match=words):
        loader(text)


def test_segments_near_box_matches_shapely_distance():
    rng = np.random.default_rng(3)
    segments = rng.uniform(-5.0, 5.0, size=(400, 2, 2))
    the_map = SegmentMap.from_segments(segments)
    for _ in range(30):
        centre = rng.uniform(-4.0, 4.0, size=2)
        half = rng.uniform(0.0, 1.5, size=2)
        box = np.stack([centre - half, centre + half], axis=1)
        distance_m = rng.uniform(0.0, 1.0)
        rectangle = shapely.box(box[0, 0], box[1, 0], box[0, 1], box[1, 1])
        lines = shapely.linestrings(segments)
        reference = shapely.distance(lines, rectangle)
        margin = np.abs(reference - distance_m) > 1e-7  # skip ties the slack may keep
        got = the_map.segments_near_box(np.vstack([box, [[-3.0, 3.0]]]), distance_m)
        expected = segments[(reference <= distance_m) & margin]
        kept = {segment.tobytes() for segment in got}
        assert all(segment.tobytes() in kept for segment in expected)
        dropped = segments[(reference > distance_m) & margin]
        assert not any(segment.tobytes() in kept for segment in dropped)


def test_segment_crossing_a_box_without_end_points_inside_is_near():
    the_map = SegmentMap.from_segments([[[-10.0, 0.5], [10.0, 0.5]], [[-10.0, 3], [10.0, 3]]])
    near = the_map.segments_near_box([[0.0, 1.0], [0.0, 1.0]], 0.0)
    np.testing.assert_array_equal(near, the_map.segments[:1])


@pytest.mark.parametrize("name", BUILTIN_MAP_NAMES)
def test_builtin_maps_are_closed_rooms(name):
    the_map = builtin_map(name)
    assert the_map.name == name
    assert the_map.boundary is not None
    polygon = shapely.Polygon(the_map.boundary)
    assert polygon.is_valid and polygon.area > 40.0
    # every wall lies inside or on the outer wall
    lines = shapely.linestrings(the_map.segments)
    assert shapely.covers(polygon.buffer(1e-9), lines).all()


def test_hall_landmarks_are_sparse_and_the_hall_is_not_symmetric():
    hall = builtin_map("hall")
    outer = shapely.LinearRing(hall.boundary)
    lines = shapely.linestrings(hall.segments)
    inner = [line for line in lines if not outer.covers(line)]
    merged = shapely.line_merge(shapely.MultiLineString(inner))
    pieces = list(shapely.get_parts(shapely.unary_union(merged.buffer(1e-6))))
    assert len(pieces) >= 3
    for i, first in enumerate(pieces):
        for second in pieces[i + 1 :]:
            assert first.distance(second) >= 3.0 - 1e-5
    # no rotation by pi about the centre maps the landmarks onto themselves
    centre = hall.bounds.mean(axis=1)
    turned = shapely.affinity.rotate(shapely.MultiLineString(inner), 180, origin=tuple(centre))
    assert turned.hausdorff_distance(shapely.MultiLineString(inner)) > 1.0
    mirrored = shapely.affinity.scale(shapely.MultiLineString(inner), -1, 1, origin=tuple(centre))
    assert mirrored.hausdorff_distance(shapely.MultiLineString(inner)) > 1.0


def test_unknown_builtin_map_names_the_choices():
    with pytest.raises(MapError, match="hall"):
        builtin_map("garage")


def _same_polygon(a: np.ndarray, b: np.ndarray) -> bool:
    return shapely.Polygon(a).normalize().equals_exact(shapely.Polygon(b).normalize(), 1e-12)


def test_a_room_gets_the_same_outer_wall_in_every_format():
    """Line strings (WKT, GeoJSON) closing a room get its boundary, as inline segments and a
    polygon do; an open wall or a wall outside the largest ring gets none."""
    room = [[0, 0], [6, 0], [6, 5], [0, 5], [0, 0]]
    polygon = SegmentMap.from_wkt("POLYGON ((0 0, 6 0, 6 5, 0 5, 0 0))").boundary
    maps = {
        "wkt multilinestring": SegmentMap.from_wkt(
            "MULTILINESTRING ((0 0, 6 0, 6 5), (6 5, 0 5, 0 0), (2 2, 3 2))"
        ),
        "wkt linestring": SegmentMap.from_wkt("LINESTRING (0 0, 6 0, 6 5, 0 5, 0 0)"),
        "geojson linestrings": SegmentMap.from_geojson(
            {
                "type": "FeatureCollection",
                "features": [
                    {
                        "type": "Feature",
                        "properties": {},
                        "geometry": {"type": "LineString", "coordinates": room[:3]},
                    },
                    {
                        "type": "Feature",
                        "properties": {},
                        "geometry": {"type": "LineString", "coordinates": room[2:]},
                    },
                ],
            }
        ),
        "inline": SegmentMap.from_segments(
            np.array([room[:-1], room[1:]], dtype=float).swapaxes(0, 1),
            boundary=outer_wall(np.array([room[:-1], room[1:]], dtype=float).swapaxes(0, 1)),
        ),
    }
    for name, segment_map in maps.items():
        assert segment_map.boundary is not None and _same_polygon(segment_map.boundary, polygon), (
            name
        )
    assert SegmentMap.from_wkt("LINESTRING (0 0, 6 0, 6 5, 0 5)").boundary is None  # not closed
    assert (
        SegmentMap.from_wkt("MULTILINESTRING ((0 0, 1 0, 1 1, 0 0), (5 5, 6 6))").boundary is None
    )


def test_nearest_segment_distance_is_the_whole_arrays_minimum_bit_for_bit():
    """The pruned nearest-wall distance against the minimum over every segment at once, on
    random segment soups and on paths (consecutive samples, as the summary passes them)."""
    rng = np.random.default_rng(7)
    for trial in range(60):
        segments = rng.uniform(-10.0, 10.0, (int(rng.integers(1, 300)), 2, 2))
        count = int(rng.integers(1, 700))
        if trial % 2:  # a path: small steps from a random start
            points = np.cumsum(rng.normal(0.0, 0.02, (count, 2)), axis=0) + rng.uniform(-5, 5, 2)
        else:
            points = rng.uniform(-12.0, 12.0, (count, 2))
        whole = point_segment_distance(points[:, None, :], segments[:, 0], segments[:, 1])
        np.testing.assert_array_equal(nearest_segment_distance(points, segments), whole.min(axis=1))


def test_nearest_segment_distance_on_a_floor_plan_skips_most_segments(monkeypatch):
    """On the office floor (495 segments) a path's blocks look at a few segments each, and
    the distances still equal the whole-map ones."""
    floor = SegmentMap.from_wkt(OFFICE_FLOOR_WKT.read_text(encoding="utf-8"))
    rng = np.random.default_rng(3)
    points = np.cumsum(rng.normal(0.0, 0.004, (1500, 2)), axis=0) + np.array([5.0, 5.0])
    seen = []
    real = maps.point_segment_distance

    def counting(p, a, b):
        seen.append(len(a))
        return real(p, a, b)

    monkeypatch.setattr(maps, "point_segment_distance", counting)
    got = nearest_segment_distance(points, floor.segments)
    monkeypatch.undo()
    whole = point_segment_distance(points[:, None, :], floor.segments[:, 0], floor.segments[:, 1])
    np.testing.assert_array_equal(got, whole.min(axis=1))
    exact_calls = seen[1::2]  # each block: the centre's distances (all), then the kept ones
    assert max(exact_calls) < len(floor.segments) // 4
